// Scene files: a JSON description of what `lockstep rollout`, `lockstep
// bench` and the vectorised environment run (the model, fixed or floating
// base, initial state, ground and static boxes, contact settings, drive
// gains, step options, environment options and randomisation ranges), read
// into a ready-to-run Scene. The format: docs/scenes.md.
//
//   lockstep::Scene scene = lockstep::load_scene("models/quadruped_scene.json");
//   lockstep::VecEnv env(scene.model, 4096, scene.env);
#pragma once

#include "batch/vec_env.hpp"
#include "layout/model.hpp"

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace lockstep {

// Any invalid scene input: a syntax error ("FILE:LINE:COLUMN: what"), a model
// that does not load, or a key that is unknown, of the wrong type, out of
// range or not finite ("FILE: key.path: what is wrong").
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Scene {
  std::string source;      // the scene file, or the URDF for a bare model
  std::string model_path;  // the URDF (a scene file's relative path resolved against its folder)
  bool floating_base = false;
  Model model;
  std::vector<std::string> warnings;  // from the URDF import
  // Values the file gives that look wrong, each naming its key: a joint
  // position outside the joint's limits (the CLI prints them)
  std::vector<std::string> value_warnings;
  // Step options with contacts; dofs: default_dof_settings(model) with the
  // file's drives and joint dynamics, one per DOF; the environment options,
  // randomisation and initial state (empty: the neutral configuration at
  // rest).
  VecEnvOptions env;
};

// Reads a .json scene file. Throws SceneError.
Scene load_scene(const std::string& path);

// A bare URDF with the defaults: no ground unless `ground` (then the plane
// z = 0 with the default surface), contacts among the model's shapes as the
// default ContactSettings give them, no drives beyond the URDF's settings,
// the initial state neutral at rest; with a ground and a floating base, the
// root raised to resting_root_height (the robot starts touching the ground,
// not inside it). Throws SceneError.
Scene scene_from_urdf(const std::string& urdf_path, bool floating_base, bool ground);

// The height z of q's floating roots at which the lowest point of the
// model's collision shapes (on moving bodies) touches the plane z = 0, the
// rest of q as given; nullopt when no moving body has a shape.
std::optional<double> resting_root_height(const Model& model, Eigen::VectorXd q);

// A scene file when `path` ends in ".json", else a bare URDF. For a scene
// file, `floating_base` and `ground` override the file only when true: the
// model is loaded with a floating base, and a scene without a ground gets
// the default plane (a ground the file describes is kept as it is).
Scene load_scene_or_urdf(const std::string& path, bool floating_base, bool ground);

// Contacts off entirely (`--no-contacts`): Stage::Contacts forced Off.
void disable_contacts(Scene& scene);

// A warning when the scene's initial state (the neutral configuration
// when it has none) starts a shape more than 1 cm inside its ground, with
// contacts on: the contacts would push it out at up to their depenetration
// speed. Derived from the scene as it is, so ask after changing its state,
// ground or contacts (`lockstep rollout` and `bench` ask after posing a
// bare URDF and applying --no-contacts).
std::optional<std::string> ground_start_warning(const Scene& scene);

// The scene as scene-file JSON that load_scene reads back to the same
// options, bit for bit (every value written explicitly, the model path
// absolute), e.g. to record in a rollout exactly what ran. Throws
// std::invalid_argument for a Scene the format cannot express (a DofSettings
// field other than the drive gains, max_force, drive type, damping and
// friction changed from the model's defaults; a stage other than contacts
// forced; the DOFs of one joint, or the shapes of one link, set
// differently). A quaternion not unit to rounding reads back normalised.
std::string scene_to_json(const Scene& scene);

}  // namespace lockstep
