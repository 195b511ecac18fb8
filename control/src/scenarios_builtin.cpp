// The paper's experiments (Sec. 8) as scenarios for the kinematic simulation. Coordinates are in the
// world frame of the shipped robot: floor, x forward, y left, z up; the robot starts at the origin.
#include "reflex/control/scenarios.hpp"

#include <cmath>

namespace reflex::control {
namespace {

void give(ControlInput& in, int arm, double x, double y, double z) {
  in.hands[arm].status = HandStatus::kGiven;
  in.hands[arm].target_W = Eigen::Vector3d(x, y, z);
}

void none(ControlInput& in, int arm) { in.hands[arm].status = HandStatus::kNoTarget; }

std::vector<Scenario> makeScenarios() {
  std::vector<Scenario> list;
  {
    Scenario s;
    s.name = "target_inside_body";
    s.paper = "Sec. 8.2.1, Fig. 5";
    s.description = "the right hand's target is inside the body: the arm stops at the side of the body";
    s.duration = 6.0;
    s.script = [](double, ControlInput& in, ScenarioContext&) {
      none(in, kLeft);
      give(in, kRight, 0.02, -0.06, 0.66);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "through_body";
    s.paper = "Sec. 8.2.2, Figs. 6-7";
    s.description = "the straight path from beside the body to a target in front of it passes through the "
                    "body: the wrist goes around it";
    s.duration = 7.0;
    s.script = [](double t, ControlInput& in, ScenarioContext&) {
      none(in, kLeft);
      if (t < 2.0) give(in, kRight, -0.10, -0.33, 0.80);
      else give(in, kRight, 0.30, -0.05, 0.85);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "one_vs_three_dof";
    s.paper = "Sec. 8.2.2, Figs. 8-9";
    s.description = "the same reach with 1-DOF and 3-DOF avoidance (reflex_sim runs both): the 1-DOF "
                    "controller keeps more joints for reaching and arrives sooner";
    s.duration = 8.0;
    s.script = [](double t, ControlInput& in, ScenarioContext&) {
      none(in, kLeft);
      if (t < 2.0) give(in, kRight, -0.10, -0.33, 0.80);
      else give(in, kRight, 0.27, 0.03, 0.82);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "crossing_arms";
    s.paper = "Sec. 8.3.1, Fig. 10";
    s.description = "static targets in front of the body that make the arms cross: the forearms stop close to d_b";
    s.duration = 5.0;
    s.script = [](double, ControlInput& in, ScenarioContext&) {
      give(in, kLeft, 0.30, -0.08, 0.90);
      give(in, kRight, 0.30, 0.08, 0.90);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "walking_target_behind";
    s.paper = "Sec. 8.3.2, Fig. 11";
    s.description = "the right hand's target is 0.8 m in front of the start; the robot walks 1.5 m forward so "
                    "the target ends up behind it: the arm does not penetrate the body";
    s.duration = 9.0;
    s.walk_distance = 1.5;
    s.walk_speed = 0.25;
    s.walk_start = 0.5;
    s.script = [](double, ControlInput& in, ScenarioContext&) {
      none(in, kLeft);
      give(in, kRight, 0.80, -0.12, 0.85);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "grasped_bar";
    s.paper = "Sec. 8.5.1, Fig. 14";
    s.description = "a bar held in the left hand is part of the body schema with higher motion priority: "
                    "the right arm avoids the bar while both hands have targets";
    s.duration = 8.0;
    s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
      if (t == 0.0)
        ctx.attach(0, "l_hand", Eigen::Vector3d(-0.16, 0.0, -0.06), Eigen::Vector3d(0.16, 0.0, -0.06), 0.015, false,
                   {"l_hand", "l_forearm"});
      in.priority = MotionPriority::kLeftHigher;
      // The left hand sweeps the bar in a circle in front of the chest; the right hand holds a target
      // inside the bar's sweep.
      const double w = 2.0 * M_PI / 4.0;
      give(in, kLeft, 0.30, 0.02 + 0.10 * std::cos(w * t), 0.92 + 0.08 * std::sin(w * t));
      give(in, kRight, 0.30, -0.02, 0.90);
    };
    list.push_back(s);
  }
  {
    Scenario s;
    s.name = "occlusion";
    s.paper = "Sec. 8.5.2, Fig. 15";
    s.description = "a virtual capsule from the head camera to the looked-at object: the right hand's path "
                    "across the face goes around the gaze line";
    s.duration = 8.0;
    s.script = [](double t, ControlInput& in, ScenarioContext& ctx) {
      const Eigen::Vector3d object(0.45, 0.05, 0.92);
      const int cam = ctx.model.linkIndex("head_camera");
      if (cam < 0)  // the gaze line starts at the camera: no camera link, no experiment (never a guess)
        throw ConfigError("scenario 'occlusion' needs the camera link 'head_camera', which robot '" + ctx.model.name +
                          "' does not have");
      const Eigen::Vector3d camera = ctx.data.kin.X_W_L[cam].translation();
      // The gaze line, re-attached every cycle as the head and object move; in the world frame.
      ctx.attach(1, ctx.model.links[0].name, camera, object, 0.03, true, {"head"});
      none(in, kLeft);
      const double phase = 0.5 - 0.5 * std::cos(2.0 * M_PI * t / 4.0);  // right -> left -> right
      give(in, kRight, 0.32, -0.25 + 0.38 * phase, 1.00);
    };
    list.push_back(s);
  }
  return list;
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
