// Hints for misspelled names: the distance they rest on, and which names
// they offer.
#include "layout/name_hint.hpp"

#include <gtest/gtest.h>

#include "test_support.hpp"

namespace lockstep {
namespace {

TEST(NameDistance, CountsEachEditOnceIgnoringCase) {
  EXPECT_EQ(name_distance("knee", "knee"), 0);
  EXPECT_EQ(name_distance("KNEE", "knee"), 0);
  EXPECT_EQ(name_distance("", "knee"), 4);
  EXPECT_EQ(name_distance("knee", ""), 4);
  EXPECT_EQ(name_distance("kne", "knee"), 1);     // insertion
  EXPECT_EQ(name_distance("kneee", "knee"), 1);   // deletion
  EXPECT_EQ(name_distance("knae", "knee"), 1);    // substitution
  EXPECT_EQ(name_distance("kene", "knee"), 1);    // neighbours swapped
  EXPECT_EQ(name_distance("FL_knee", "FR_knee"), 1);
  EXPECT_EQ(name_distance("hip", "knee"), 4);
  EXPECT_EQ(name_distance("abc", "cba"), 2);
}

TEST(DidYouMean, OffersTheClosestNameWithinOneEditPerThreeCharacters) {
  const std::vector<std::string> joints = {"FL_hip", "FL_knee", "FR_knee", "HL_knee"};
  EXPECT_EQ(did_you_mean("FL_kne", joints), " (did you mean \"FL_knee\"?)");
  EXPECT_EQ(did_you_mean("fl_knee", joints), " (did you mean \"FL_knee\"?)");
  // Two candidates one edit away: the first in order.
  EXPECT_EQ(closest_name("FX_knee", joints), "FL_knee");
  // "knee" (4 characters) allows one edit; FL_knee is three away.
  EXPECT_EQ(did_you_mean("knee", joints), "");
  EXPECT_EQ(did_you_mean("elbow", joints), "");
  EXPECT_EQ(did_you_mean("x", {}), "");
  // One edit is allowed even for the shortest names.
  EXPECT_EQ(closest_name("qdd", {"q", "qd", "tau"}), "qd");
}

TEST(DidYouMean, ModelLookupsNameTheClosestLinkJointAndDof) {
  const Model model = test::load_shared_model("anymal_b", true);
  const auto message = [](auto&& lookup) {
    try {
      lookup();
    } catch (const std::out_of_range& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message([&] { return model.joint_index("LF_KFF"); }),
            "model has no moving joint named 'LF_KFF' (did you mean \"LF_KFE\"?)");
  EXPECT_EQ(message([&] { return model.frame_index("LF_SHNK"); }),
            "model has no link named 'LF_SHNK' (did you mean \"LF_SHANK\"?)");
  EXPECT_EQ(message([&] { return model.dof_index("RH_HAA "); }),
            "model has no DOF named 'RH_HAA ' (did you mean \"RH_HAA\"?)");
  EXPECT_EQ(message([&] { return model.articulation_index("anymall"); }),
            "model has no articulation named 'anymall' (did you mean \"anymal\"?)");
  EXPECT_EQ(message([&] { return model.joint_index("wrist"); }), "model has no moving joint named 'wrist'");
}

}  // namespace
}  // namespace lockstep
