// The paper's experiments (Sec. 8) as scenarios for the kinematic simulation. Coordinates are
// written in the world frame of the reference robot (asimo_like: floor, x forward, y left, z up; the
// robot starts at the origin) and placed on the robot that runs them through its own landmarks
// (ScenarioFrame::place: shoulders, chest, arm length at the rest posture); on the reference robot
// they are these numbers exactly.
#include "reflex/control/onboard.hpp"
#include "reflex/control/scenarios.hpp"

#include <algorithm>
#include <cmath>

namespace reflex::control {
namespace {

/// Gives `arm` the target p_ref (reference robot coordinates) placed on this robot.
void give(ControlInput& in, ScenarioContext& ctx, int arm, double x, double y, double z) {
  in.hands[arm].status = HandStatus::kGiven;
  in.hands[arm].target_B = ctx.frame().place(Eigen::Vector3d(x, y, z));
}

/// Gives `arm` the target p_ref (reference robot coordinates) placed on this robot, as a target the
/// scenario means it to reach: moved within the arm's reach where this robot's arm cannot get there.
void reach(ControlInput& in, ScenarioContext& ctx, int arm, double x, double y, double z) {
  in.hands[arm].status = HandStatus::kGiven;
  in.hands[arm].target_B = ctx.reachable(arm, ctx.frame().place(Eigen::Vector3d(x, y, z)));
}

/// The segment on `link` (or what it is fixed to) a scenario needs; a ConfigError naming the
/// scenario, the link, what it is for and the robot if there is none.
int neededSegment(const ScenarioContext& ctx, const char* scenario, const std::string& link, const char* role) {
  const int s = ctx.carrierSegment(ctx.model.linkIndex(link));
  if (s < 0)
    throw ConfigError(std::string("scenario '") + scenario + "' needs collision geometry on " + role + " '" + link +
                      "' (or on a link it is fixed to), which robot '" + ctx.model.name + "' does not have");
  return s;
}

void none(ControlInput& in, int arm) { in.hands[arm].status = HandStatus::kNoTarget; }

Scenario targetInsideBody() {
  Scenario s;
  s.name = "target_inside_body";
  s.paper = "Sec. 8.2.1, Fig. 5";
  s.description = "the right hand's target is inside the body: the arm stops at the side of the body";
  s.duration = 6.0;
  s.script = [](double, ControlInput& in, ScenarioContext& ctx) {
    none(in, kLeft);
    give(in, ctx, kRight, 0.02, -0.06, 0.66);
  };
  return s;
}

Scenario throughBody() {
  Scenario s;
  s.name = "through_body";
  s.paper = "Sec. 8.2.2, Figs. 6-7";
  s.description =
      "the straight path from beside the body to a target in front of it passes through the "
      "body: the wrist goes around it";
  s.duration = 7.0;
  s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
    none(in, kLeft);
    if (t < 2.0)
      reach(in, ctx, kRight, -0.10, -0.33, 0.80);
    else
      reach(in, ctx, kRight, 0.30, -0.05, 0.85);
  };
  return s;
}

Scenario oneVsThreeDof() {
  Scenario s;
  s.name = "one_vs_three_dof";
  s.paper = "Sec. 8.2.2, Figs. 8-9";
  s.description =
      "the same reach with 1-DOF and 3-DOF avoidance (reflex_sim runs both): the 1-DOF "
      "controller keeps more joints for reaching and arrives sooner";
  s.duration = 8.0;
  s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
    none(in, kLeft);
    if (t < 2.0)
      reach(in, ctx, kRight, -0.10, -0.33, 0.80);
    else
      reach(in, ctx, kRight, 0.27, 0.03, 0.82);
  };
  return s;
}

Scenario crossingArms() {
  Scenario s;
  s.name = "crossing_arms";
  s.paper = "Sec. 8.3.1, Fig. 10";
  s.description = "static targets in front of the body that make the arms cross: the forearms stop close to d_b";
  s.duration = 5.0;
  s.script = [](double, ControlInput& in, ScenarioContext& ctx) {
    give(in, ctx, kLeft, 0.30, -0.08, 0.90);
    give(in, ctx, kRight, 0.30, 0.08, 0.90);
  };
  return s;
}

Scenario walkingTargetBehind() {
  Scenario s;
  s.name = "walking_target_behind";
  s.paper = "Sec. 8.3.2, Fig. 11";
  s.description =
      "the right hand's target is 0.8 m in front of the start; the robot walks 1.5 m forward so "
      "the target ends up behind it: the arm does not penetrate the body";
  s.duration = 9.0;
  s.walk_distance = 1.5;
  s.walk_speed = 0.25;
  s.walk_start = 0.5;
  s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
    none(in, kLeft);
    give(in, ctx, kRight, 0.80, -0.12, 0.85);
    // A robot whose root does not walk (no heel_x joint: the legs swing, the root stays) sees the
    // target come towards it and pass it as it would walking: the target moves back in the root
    // frame by the distance walked (1.5 m at 0.25 m/s from t = 0.5 s, as startWalking is asked),
    // in proportion to the arm like the target.
    if (ctx.model.qIndex("heel_x") < 0)
      in.hands[kRight].target_B -= ctx.frame().axes.col(0) * ctx.frame().length(std::clamp(0.25 * (t - 0.5), 0.0, 1.5));
  };
  return s;
}

Scenario graspedBar() {
  Scenario s;
  s.name = "grasped_bar";
  s.paper = "Sec. 8.5.1, Fig. 14";
  s.description =
      "a bar held in the left hand is part of the body schema with higher motion priority: "
      "the right arm avoids the bar while both hands have targets";
  s.duration = 8.0;
  s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
    if (t == 0.0) {
      // The bar lies across the left hand (the controller configuration's hand link) through its
      // hand point, along the hand frame's x axis: 0.32 m long and 15 mm thick on the reference robot,
      // both in proportion to the arm on another. It is not checked against what holds it: the hand,
      // every link fixed to it, its fingers, and the wrist it hangs from (graspIgnoreMask, the rule a
      // grasped object sent over the bus gets too).
      const ControllerModel::Arm& arm = ctx.cm.arms[kLeft];
      const std::string& hand = ctx.model.links[static_cast<std::size_t>(arm.hand_link)].name;
      (void)neededSegment(ctx, "grasped_bar", hand, "the left hand link");
      const std::uint64_t mask = graspIgnoreMask(ctx.model, ctx.cm, arm.hand_link);
      std::vector<std::string> ignore;
      for (int seg = 0; seg < ctx.model.num_robot_segments; ++seg)
        if ((mask >> seg) & 1U) ignore.push_back(ctx.model.segments[static_cast<std::size_t>(seg)].name);
      // Across the hand, not along the forearm: the hand frame's axis most perpendicular to the
      // direction from the wrist to the hand point (x on the reference robot, whose hand points down
      // its z; z on a robot whose hand frame points along x).
      Eigen::Vector3d across = Eigen::Vector3d::UnitX();
      if (const double n = arm.hand_point_L.norm(); n > 1e-9) {
        int best = 0;
        for (int k = 1; k < 3; ++k)
          if (std::abs(arm.hand_point_L[k]) < std::abs(arm.hand_point_L[best]) - 1e-9 * n) best = k;
        across = Eigen::Vector3d::Unit(best);
      }
      const double half = ctx.frame().length(0.16);
      ctx.attach(0, hand, arm.hand_point_L - half * across, arm.hand_point_L + half * across, ctx.frame().length(0.015),
                 false, ignore);
    }
    in.priority = MotionPriority::kLeftHigher;
    // The left hand sweeps the bar in a circle in front of the chest; the right hand holds a target
    // inside the bar's sweep.
    const double w = 2.0 * M_PI / 4.0;
    give(in, ctx, kLeft, 0.30, 0.02 + 0.10 * std::cos(w * t), 0.92 + 0.08 * std::sin(w * t));
    give(in, ctx, kRight, 0.30, -0.02, 0.90);
  };
  return s;
}

Scenario occlusion() {
  Scenario s;
  s.name = "occlusion";
  s.paper = "Sec. 8.5.2, Fig. 15";
  s.description =
      "a virtual capsule from the head camera to the looked-at object: the right hand's path "
      "across the face goes around the gaze line";
  s.duration = 8.0;
  s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
    const Eigen::Vector3d object = ctx.frame().place(Eigen::Vector3d(0.45, 0.05, 0.92));
    const int cam = ctx.model.linkIndex(ctx.camera_link);
    if (cam < 0)  // the gaze line starts at the camera: no camera link, no experiment (never a guess)
      throw ConfigError("scenario 'occlusion' needs the camera link '" + ctx.camera_link + "', which robot '" +
                        ctx.model.name + "' does not have (camera_link in the controller configuration)");
    // The head the camera is fixed to: the gaze line starts inside it and is not checked against it.
    const int head = neededSegment(ctx, "occlusion", ctx.camera_link, "the camera link");
    const Eigen::Vector3d camera = ctx.data.kin.X_B_L[cam].translation();
    // The gaze line, re-attached every cycle as the head and object move; in the world frame.
    ctx.attach(1, ctx.model.links[0].name, camera, object, ctx.frame().length(0.03), true,
               {ctx.model.segments[static_cast<std::size_t>(head)].name});
    none(in, kLeft);
    const double phase = 0.5 - 0.5 * std::cos(2.0 * M_PI * t / 4.0);  // right -> left -> right
    give(in, ctx, kRight, 0.32, -0.25 + 0.38 * phase, 1.00);
  };
  return s;
}

std::vector<Scenario> makeScenarios() {
  return {targetInsideBody(),    throughBody(), oneVsThreeDof(), crossingArms(),
          walkingTargetBehind(), graspedBar(),  occlusion()};
}

}  // namespace

const std::vector<Scenario>& builtinScenarios() {
  static const std::vector<Scenario> scenarios = makeScenarios();
  return scenarios;
}

const Scenario* findScenario(const std::string& name) {
  for (const auto& s : builtinScenarios())
    if (s.name == name) return &s;
  return nullptr;
}

}  // namespace reflex::control
