// URDF mesh collisions become boxes fitted to the mesh file's vertices
// (io/mesh_bounds.hpp, docs/contacts.md): binary and ASCII STL, OBJ and
// COLLADA files with scale and origin; unreadable files are skipped with a
// warning and the rest of the model loads; a fitted box stands on the ground.
#include "batch/simulator.hpp"
#include "io/urdf_import.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace lockstep {
namespace {

namespace fs = std::filesystem;

// The test's own folder <tmp>/lockstep_mesh_fit_<test>_<pid>/mypkg, with
// urdf/ and meshes/ inside; ctest runs test cases side by side.
class MeshFit : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("lockstep_mesh_fit_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
             std::to_string(::getpid()));
    pkg_ = root_ / "mypkg";
    fs::create_directories(pkg_ / "urdf");
    fs::create_directories(pkg_ / "meshes");
  }
  void TearDown() override { fs::remove_all(root_); }

  // Writes `text` to `relative` (under the package) and returns the path.
  fs::path write(const std::string& relative, const std::string& text) const {
    const fs::path path = pkg_ / relative;
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }

  fs::path root_, pkg_;
};

const char* kInertial = R"(<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>)";

std::string robot(const std::string& link_body) {
  return "<robot name=\"bot\">\n<link name=\"base\">\n" + link_body + "</link>\n</robot>\n";
}

std::string mesh_collision(const std::string& file, const std::string& attributes = "",
                           const std::string& origin = "") {
  return "<collision>" + origin + "<geometry><mesh filename=\"" + file + "\"" + attributes + "/></geometry></collision>\n";
}

// The 1-based line of `text` where `piece` first appears.
int line_of(const std::string& text, const std::string& piece) {
  const std::string before = text.substr(0, text.find(piece));
  return 1 + static_cast<int>(std::count(before.begin(), before.end(), '\n'));
}

// A binary STL of the 12 triangles of the box [lo, hi]. Its header begins
// with "solid", as many exporters' do: the size, not that word, makes it binary.
std::string binary_stl_box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  std::string bytes = "solid written as binary";
  bytes.resize(80, ' ');
  auto put32 = [&](std::uint32_t x) {
    for (int k = 0; k < 4; ++k) bytes.push_back(static_cast<char>(x >> (8 * k) & 0xff));
  };
  auto corner = [&](int i) {
    return Eigen::Vector3f(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(), i & 4 ? hi.z() : lo.z());
  };
  const int faces[6][4] = {{0, 1, 3, 2}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 3, 7, 5}};
  put32(12);
  for (const auto& f : faces)
    for (const auto& tri : {std::array<int, 3>{f[0], f[1], f[2]}, std::array<int, 3>{f[0], f[2], f[3]}}) {
      for (int k = 0; k < 3; ++k) put32(0);  // normal, unused
      for (int v : tri)
        for (int k = 0; k < 3; ++k) {
          std::uint32_t bits;
          const float x = corner(v)[k];
          std::memcpy(&bits, &x, sizeof bits);
          put32(bits);
        }
      bytes += std::string(2, '\0');  // attribute byte count
    }
  return bytes;
}

// The offset cube of these tests: [0.5, 0.75] x [-0.25, 0.5] x [1, 1.5].
const Eigen::Vector3d kCubeLo(0.5, -0.25, 1.0), kCubeHi(0.75, 0.5, 1.5);
std::string cube_stl() { return binary_stl_box(kCubeLo.cast<float>(), kCubeHi.cast<float>()); }

Eigen::Isometry3d translation(const Eigen::Vector3d& t) { return Eigen::Isometry3d(Eigen::Translation3d(t)); }

void expect_box(const Shape& s, const Eigen::Vector3d& half, const Eigen::Isometry3d& pose) {
  EXPECT_EQ(s.type, ShapeType::Box) << s.mesh_path;
  EXPECT_LT((s.size - half).cwiseAbs().maxCoeff(), 1e-12) << s.mesh_path << ": " << s.size.transpose();
  EXPECT_LT((s.pose.matrix() - pose.matrix()).cwiseAbs().maxCoeff(), 1e-12) << s.mesh_path << ":\n" << s.pose.matrix();
}

// The warning that names `file`, or "" when none does (and a failure).
std::string warning_naming(const std::vector<std::string>& warnings, const std::string& file) {
  for (const std::string& w : warnings)
    if (w.find("'" + file + "'") != std::string::npos) return w;
  ADD_FAILURE() << "no warning names '" << file << "'";
  return "";
}

TEST_F(MeshFit, EachFormatBecomesTheBoxOfItsScaledVertices) {
  write("meshes/cube.stl", cube_stl());
  write("meshes/part.STL", R"(solid part
  facet normal 0 0 1
    outer loop
      vertex 0 0 0
      vertex 0.5 0.25 0
      vertex +0.125 -0.5 7.5e-1
    endloop
  endfacet
endsolid part
)");
  write("urdf/mesh.obj", "# comment\no thing\nv 1 2 3\nv -1 0.5 2 1.0\nvt 5 5\nvn 9 9 9\nf 1 2 1\n");
  write("urdf/flat.obj", "v 0 0 0.25\nv 1 0 0.25\nv 0 2 0.25\n");
  // Centimetres, y up; the normals source comes first, so the POSITION input
  // must be followed by id; geometry b has an accessor of stride 4; the node
  // matrix (a 5-unit shift) is ignored.
  write("meshes/y_up.dae", R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="centimeter" meter="0.01"/><up_axis> Y_UP </up_axis></asset>
  <library_geometries>
    <geometry id="a"><mesh>
      <source id="a-normals"><float_array id="a-normals-array" count="3">99 99 99</float_array></source>
      <source id="a-positions">
        <float_array id="a-positions-array" count="6">10 20 30 -10 0 50</float_array>
        <technique_common><accessor source="#a-positions-array" count="2" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
        </accessor></technique_common>
      </source>
      <vertices id="a-vertices"><input semantic="POSITION" source="#a-positions"/></vertices>
      <triangles count="0"/>
    </mesh></geometry>
    <geometry id="b"><mesh>
      <source id="b-positions"><float_array id="b-array" count="8">0 0 0 9 -20 40 10 9</float_array>
        <technique_common><accessor source="#b-array" count="2" stride="4"/></technique_common></source>
      <vertices id="b-vertices"><input semantic="POSITION" source="#b-positions"/></vertices>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes><visual_scene id="scene"><node>
    <matrix>1 0 0 5 0 1 0 5 0 0 1 5 0 0 0 1</matrix><instance_geometry url="#a"/>
  </node></visual_scene></library_visual_scenes>
</COLLADA>
)");
  const std::string origin = R"(<origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.5"/>)";
  const std::string urdf = robot(std::string(kInertial) + "\n" +                                 //
                                 mesh_collision("package://mypkg/meshes/cube.stl") +              //
                                 mesh_collision("package://mypkg/meshes/cube.stl", " scale=\"2 -1 0.5\"", origin) +
                                 mesh_collision("../meshes/part.STL") +                           //
                                 mesh_collision("mesh.obj") +                                     //
                                 mesh_collision("package://mypkg/meshes/y_up.dae") +              //
                                 mesh_collision("flat.obj"));
  const fs::path file = write("urdf/robot.urdf", urdf);
  UrdfOptions options;
  options.floating_base = true;
  std::vector<std::string> warnings;
  const Model model = load_urdf(file.string(), options, {}, &warnings);
  ASSERT_EQ(model.shapes.size(), 6u);
  const std::vector<Shape>& s = model.shapes;

  // cube: [0.5, 0.75] x [-0.25, 0.5] x [1, 1.5]
  expect_box(s[0], Eigen::Vector3d(0.125, 0.375, 0.25), translation(Eigen::Vector3d(0.625, 0.125, 1.25)));
  EXPECT_TRUE(fs::equivalent(s[0].mesh_path, pkg_ / "meshes" / "cube.stl"));
  // scaled by (2, -1, 0.5), y mirrored: [1, 1.5] x [-0.5, 0.25] x [0.5, 0.75], then the origin
  const Eigen::Isometry3d collision_origin =
      translation(Eigen::Vector3d(0.1, 0.2, 0.3)) *
      Eigen::Isometry3d(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
                        Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()));
  expect_box(s[1], Eigen::Vector3d(0.25, 0.375, 0.125), collision_origin * translation(Eigen::Vector3d(1.25, -0.125, 0.625)));
  EXPECT_EQ(s[1].mesh_scale, Eigen::Vector3d(2, -1, 0.5));
  // ASCII STL: (0, 0, 0), (0.5, 0.25, 0), (0.125, -0.5, 0.75)
  expect_box(s[2], Eigen::Vector3d(0.25, 0.375, 0.375), translation(Eigen::Vector3d(0.25, -0.125, 0.375)));
  EXPECT_TRUE(fs::equivalent(s[2].mesh_path, pkg_ / "meshes" / "part.STL"));
  // OBJ: (1, 2, 3), (-1, 0.5, 2); vt and vn lines are not positions
  expect_box(s[3], Eigen::Vector3d(1, 0.75, 0.5), translation(Eigen::Vector3d(0, 1.25, 2.5)));
  // DAE: (x, y, z) cm y up -> (x, -z, y) / 100 m: (0.1, -0.3, 0.2), (-0.1, -0.5, 0), (0, 0, 0), (-0.2, -0.1, 0.4)
  expect_box(s[4], Eigen::Vector3d(0.15, 0.25, 0.2), translation(Eigen::Vector3d(-0.05, -0.25, 0.2)));
  // flat: zero extent along z
  expect_box(s[5], Eigen::Vector3d(0.5, 1, 0), translation(Eigen::Vector3d(0.5, 1, 0.25)));

  ASSERT_EQ(warnings.size(), 6u);
  for (const std::string& w : warnings) {
    EXPECT_EQ(w.rfind(file.string() + ":", 0), 0u) << w;
    EXPECT_NE(w.find(": link 'base': mesh file '"), std::string::npos) << w;
    EXPECT_NE(w.find("' fitted with a box "), std::string::npos) << w;
  }
  EXPECT_EQ(warnings[0], file.string() + ":" + std::to_string(line_of(urdf, "cube.stl")) +
                             ": link 'base': mesh file 'package://mypkg/meshes/cube.stl' fitted with a box 0.25 x 0.75 x "
                             "0.5 m centred at (0.625, 0.125, 1.25) in the mesh frame");
}

TEST_F(MeshFit, UnreadableMeshIsSkippedWithAWarningAndTheRestLoads) {
  const std::string cube = cube_stl();
  write("meshes/truncated.stl", cube.substr(0, cube.size() - 10));
  write("meshes/part.ply", "ply\nformat ascii 1.0\n");
  write("meshes/empty.obj", "# nothing here\n");
  write("meshes/broken.dae", "<COLLADA><library_geometries>");
  write("meshes/good.obj", "v 0 0 0\nv 0.25 0.5 1\n");
  const std::string urdf = robot(std::string(kInertial) + "\n" +
                                 "<collision><geometry><box size=\"0.2 0.4 0.6\"/></geometry></collision>\n" +
                                 mesh_collision("../meshes/truncated.stl") + mesh_collision("../meshes/part.ply") +
                                 mesh_collision("../meshes/empty.obj") + mesh_collision("../meshes/broken.dae") +
                                 mesh_collision("../meshes/missing.stl") + mesh_collision("../meshes/good.obj"));
  const fs::path file = write("urdf/robot.urdf", urdf);
  std::vector<std::string> warnings;
  const Model model = load_urdf(file.string(), {}, {}, &warnings);
  ASSERT_EQ(model.shapes.size(), 2u);
  EXPECT_EQ(model.shapes[0].size, Eigen::Vector3d(0.1, 0.2, 0.3));
  expect_box(model.shapes[1], Eigen::Vector3d(0.125, 0.25, 0.5), translation(Eigen::Vector3d(0.125, 0.25, 0.5)));

  ASSERT_EQ(warnings.size(), 6u);
  // file:line: link 'base': mesh file 'ref' (resolved path): reason; collision geometry skipped
  const std::pair<const char*, const char*> skipped[] = {
      {"../meshes/truncated.stl", "not ASCII STL; as binary STL, its header counts 12 triangles (84 + 50 x 12 = 684 bytes) but the file has 674 bytes"},
      {"../meshes/part.ply", "extension '.ply': not a mesh format read here (.stl, .obj, .dae)"},
      {"../meshes/empty.obj", "no vertices"},
      {"../meshes/broken.dae", "COLLADA: line 1: not valid XML"},
  };
  for (const auto& [ref, reason] : skipped) {
    const std::string w = warning_naming(warnings, ref);
    const std::string resolved = (pkg_ / "meshes" / fs::path(ref).filename()).string();
    EXPECT_EQ(w.rfind(file.string() + ":" + std::to_string(line_of(urdf, ref)) + ": link 'base': mesh file '" + ref +
                          "' (" + resolved + "): " + reason, 0),
              0u)
        << w;
    EXPECT_NE(w.find("; collision geometry skipped"), std::string::npos) << w;
  }
  // a missing file keeps its warning
  EXPECT_EQ(warning_naming(warnings, "../meshes/missing.stl"),
            file.string() + ":" + std::to_string(line_of(urdf, "missing.stl")) +
                ": link 'base': mesh file '../meshes/missing.stl' not found; collision geometry skipped");
  EXPECT_NE(warning_naming(warnings, "../meshes/good.obj").find("fitted with a box"), std::string::npos);
}

// A free link whose only collision is the offset cube (its mass centred in
// it) dropped from 5 cm lands on the ground and stays there: after 1 s its
// lowest corner is within 1 mm of z = 0 and it is at rest.
TEST_F(MeshFit, FittedBoxRestsOnTheGround) {
  write("meshes/cube.stl", cube_stl());
  const std::string inertial = R"(<inertial><origin xyz="0.625 0.125 1.25"/><mass value="1"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>)";
  const fs::path file = write("urdf/robot.urdf", robot(inertial + mesh_collision("../meshes/cube.stl")));
  UrdfOptions options;
  options.floating_base = true;
  const Model model = load_urdf(file.string(), options);
  ASSERT_EQ(model.shapes.size(), 1u);
  const Shape& box = model.shapes[0];
  ASSERT_EQ(box.type, ShapeType::Box);

  // The lowest point of the box over the ground for a Free joint's q.
  auto lowest = [&](const Eigen::VectorXd& q) {
    const Eigen::Isometry3d body =
        Eigen::Translation3d(Eigen::Vector3d(q.head<3>())) * Eigen::Quaterniond(q[3], q[4], q[5], q[6]);
    const Eigen::Isometry3d pose = body * box.pose;
    return pose.translation().z() - pose.linear().row(2).cwiseAbs().dot(box.size);
  };
  StepOptions o;
  o.precision = Precision::Double;
  o.contacts.ground = true;
  Simulator sim(model, 1, o);
  EXPECT_TRUE(sim.contact_pairs().notes.empty());
  Eigen::VectorXd q(7);
  q << 0, 0, 0, 1, 0, 0, 0;
  q[2] = 0.05 - lowest(q);
  sim.set_state(0, q, Eigen::VectorXd::Zero(6));
  sim.step(500);
  EXPECT_NEAR(lowest(sim.q(0)), 0.0, 1e-3);
  EXPECT_LT(sim.v(0).norm(), 1e-3);
  EXPECT_FALSE(sim.contacts(0).empty());
}

}  // namespace
}  // namespace lockstep
