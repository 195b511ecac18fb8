/* The Reflex bus test samples (variant k = 7 of tests/bus/samples.hpp) written a second time, in C,
 * against the Cyclone DDS types that idlc generates from the same idl/ files. The Cyclone
 * programs fill and check samples with these functions; the Fast DDS programs with samples.hpp. Two
 * independent codings of the same values: a layout or encoding mismatch between the vendors shows up
 * as a field difference.
 *
 * Interop types: joint_state (string + double sequences), control_status (nested structs, enums,
 * booleans, uint64), hand_targets (reliable transient-local, extremes), body_schema (keyed). */
#ifndef REFLEX_TESTS_BUS_CYCLONE_SAMPLES_H
#define REFLEX_TESTS_BUS_CYCLONE_SAMPLES_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "behavior.h"
#include "control.h"

#define REFLEX_K 7

static int64_t reflex_now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* ---- checking: print every difference, return how many -------------------------------------- */

static int check_str(const char* what, const char* expected, const char* got) {
  if (got == NULL) got = "(null)";
  if (strcmp(expected, got) != 0) {
    fprintf(stderr, "%s: expected '%s', got '%s'\n", what, expected, got);
    return 1;
  }
  return 0;
}
static int check_dbl(const char* what, double expected, double got) {
  if (!(expected == got)) {
    fprintf(stderr, "%s: expected %.17g, got %.17g\n", what, expected, got);
    return 1;
  }
  return 0;
}
static int check_int(const char* what, long long expected, long long got) {
  if (expected != got) {
    fprintf(stderr, "%s: expected %lld, got %lld\n", what, expected, got);
    return 1;
  }
  return 0;
}
static int check_u64(const char* what, uint64_t expected, uint64_t got) {
  if (expected != got) {
    fprintf(stderr, "%s: expected %llu, got %llu\n", what, (unsigned long long)expected, (unsigned long long)got);
    return 1;
  }
  return 0;
}
static int check_vec(const char* what, const struct reflex_msg_Vector3* v, double x, double y, double z) {
  char buf[128];
  int n = 0;
  snprintf(buf, sizeof buf, "%s.x", what);
  n += check_dbl(buf, x, v->x);
  snprintf(buf, sizeof buf, "%s.y", what);
  n += check_dbl(buf, y, v->y);
  snprintf(buf, sizeof buf, "%s.z", what);
  n += check_dbl(buf, z, v->z);
  return n;
}
/* The header: source as expected, seq >= 1, stamp within a minute of now. */
static int check_header(const struct reflex_msg_Header* h, const char* source) {
  int n = check_str("header.source", source, h->source);
  if (h->seq < 1) {
    fprintf(stderr, "header.seq: expected >= 1, got 0\n");
    ++n;
  }
  if (llabs(h->stamp_ns - reflex_now_ns()) > 60000000000LL) {
    fprintf(stderr, "header.stamp_ns %lld is not within a minute of now\n", (long long)h->stamp_ns);
    ++n;
  }
  return n;
}

static int check_joint_state(const reflex_msg_JointState* m, const char* source) {
  int n = check_header(&m->header, source);
  n += check_int("names._length", 21, m->names._length);
  n += check_int("positions._length", 21, m->positions._length);
  n += check_int("velocities._length", 21, m->velocities._length);
  if (n) return n;
  for (int i = 0; i < 21; ++i) {
    char name[32], what[64];
    snprintf(name, sizeof name, "joint_%d", i);
    snprintf(what, sizeof what, "names[%d]", i);
    n += check_str(what, name, m->names._buffer[i]);
    snprintf(what, sizeof what, "positions[%d]", i);
    n += check_dbl(what, 0.01 * i - 1.0 + 1e-3 * REFLEX_K, m->positions._buffer[i]);
    snprintf(what, sizeof what, "velocities[%d]", i);
    n += check_dbl(what, -0.5 * i, m->velocities._buffer[i]);
  }
  return n;
}

static int check_arm(const char* arm, const reflex_msg_ArmStatus* a, double f, const char* sa, const char* sb, double d,
                     reflex_msg_Zone zone, bool estop) {
  char what[64];
  int n = 0;
  snprintf(what, sizeof what, "%s.blend_f", arm);
  n += check_dbl(what, f, a->blend_f);
  snprintf(what, sizeof what, "%s.closest_segment_a", arm);
  n += check_str(what, sa, a->closest_segment_a);
  snprintf(what, sizeof what, "%s.closest_segment_b", arm);
  n += check_str(what, sb, a->closest_segment_b);
  snprintf(what, sizeof what, "%s.distance", arm);
  n += check_dbl(what, d, a->distance);
  snprintf(what, sizeof what, "%s.zone", arm);
  n += check_int(what, zone, a->zone);
  snprintf(what, sizeof what, "%s.estop_latched", arm);
  n += check_int(what, estop, a->estop_latched);
  return n;
}

static int check_control_status(const reflex_msg_ControlStatus* m, const char* source) {
  int n = check_header(&m->header, source);
  n += check_arm("left", &m->left, 0.625, "left_forearm", "torso", 0.0125, reflex_msg_ZONE_ORANGE, false);
  n += check_arm("right", &m->right, 1.0, "right_hand", "left_hand", -0.001, reflex_msg_ZONE_RED, true);
  n += check_dbl("cycle_period_us", 5003.25, m->cycle_period_us);
  n += check_dbl("compute_time_us", 812.5 + REFLEX_K, m->compute_time_us);
  n += check_dbl("lateness_us", -3.5, m->lateness_us);
  n += check_u64("overrun_count", 0xFFFFFFFFFFFFFFF0ULL, m->overrun_count);
  n += check_dbl("arm_distance", 0.0375 + REFLEX_K, m->arm_distance);
  n += check_u64("rejected_hand_targets", 7, m->rejected_hand_targets);
  n += check_u64("rejected_body_schema", 0xFFFFFFFFFFFFFFFEULL, m->rejected_body_schema);
  n += check_u64("rejected_walk_commands", 2, m->rejected_walk_commands);
  n += check_u64("rejected_robot_states", 3, m->rejected_robot_states);
  n += check_str("last_rejection", "walk_goal_y_or_yaw_not_zero", m->last_rejection);
  return n;
}

static int check_hand_targets(const reflex_msg_HandTargets* m, const char* source) {
  int n = check_header(&m->header, source);
  n += check_int("left.status", reflex_msg_TARGET_GIVEN, m->left.status);
  n += check_vec("left.position_base", &m->left.position_base, 0.45, 0.2 + 0.01 * REFLEX_K, 0.9);
  n += check_str("left.object_name", "red_cup", m->left.object_name);
  n += check_int("right.status", reflex_msg_TARGET_NONE, m->right.status);
  n += check_vec("right.position_base", &m->right.position_base, -0.0, -1e300, 5e-324);
  n += check_str("right.object_name", "", m->right.object_name);
  return n;
}

static int check_body_schema(const reflex_msg_BodySchemaChange* m, const char* source) {
  int n = check_header(&m->header, source);
  n += check_str("segment_name", "gaze_line_7", m->segment_name);
  n += check_int("operation", reflex_msg_SCHEMA_DETACH, m->operation);
  n += check_str("parent_link", "head_link", m->parent_link);
  n += check_int("shape", reflex_msg_SHAPE_CAPSULE, m->shape);
  n += check_vec("point_a", &m->point_a, 0.05, 0.0, 0.1);
  n += check_vec("point_b", &m->point_b, 0.8, -0.3, -0.2);
  n += check_dbl("radius", 0.035, m->radius);
  n += check_int("motion_priority", -3 + REFLEX_K, m->motion_priority);
  n += check_int("enabled", false, m->enabled);
  n += check_int("virtual_segment", true, m->virtual_segment);
  return n;
}

/* ---- filling (the writer); strings point to static storage, nothing to free ------------------ */

static char reflex_joint_names[21][16];
static char* reflex_joint_name_ptrs[21];
static double reflex_positions[21];
static double reflex_velocities[21];

static void fill_joint_state(reflex_msg_JointState* m) {
  memset(m, 0, sizeof *m);
  for (int i = 0; i < 21; ++i) {
    snprintf(reflex_joint_names[i], sizeof reflex_joint_names[i], "joint_%d", i);
    reflex_joint_name_ptrs[i] = reflex_joint_names[i];
    reflex_positions[i] = 0.01 * i - 1.0 + 1e-3 * REFLEX_K;
    reflex_velocities[i] = -0.5 * i;
  }
  m->names._length = m->names._maximum = 21;
  m->names._buffer = reflex_joint_name_ptrs;
  m->positions._length = m->positions._maximum = 21;
  m->positions._buffer = reflex_positions;
  m->velocities._length = m->velocities._maximum = 21;
  m->velocities._buffer = reflex_velocities;
}

static void fill_control_status(reflex_msg_ControlStatus* m) {
  memset(m, 0, sizeof *m);
  m->left.blend_f = 0.625;
  m->left.closest_segment_a = "left_forearm";
  m->left.closest_segment_b = "torso";
  m->left.distance = 0.0125;
  m->left.zone = reflex_msg_ZONE_ORANGE;
  m->left.estop_latched = false;
  m->right.blend_f = 1.0;
  m->right.closest_segment_a = "right_hand";
  m->right.closest_segment_b = "left_hand";
  m->right.distance = -0.001;
  m->right.zone = reflex_msg_ZONE_RED;
  m->right.estop_latched = true;
  m->cycle_period_us = 5003.25;
  m->compute_time_us = 812.5 + REFLEX_K;
  m->lateness_us = -3.5;
  m->overrun_count = 0xFFFFFFFFFFFFFFF0ULL;
  m->arm_distance = 0.0375 + REFLEX_K;
  m->rejected_hand_targets = 7;
  m->rejected_body_schema = 0xFFFFFFFFFFFFFFFEULL;
  m->rejected_walk_commands = 2;
  m->rejected_robot_states = 3;
  m->last_rejection = "walk_goal_y_or_yaw_not_zero";
}

static void fill_hand_targets(reflex_msg_HandTargets* m) {
  memset(m, 0, sizeof *m);
  m->left.status = reflex_msg_TARGET_GIVEN;
  m->left.position_base.x = 0.45;
  m->left.position_base.y = 0.2 + 0.01 * REFLEX_K;
  m->left.position_base.z = 0.9;
  m->left.object_name = "red_cup";
  m->right.status = reflex_msg_TARGET_NONE;
  m->right.position_base.x = -0.0;
  m->right.position_base.y = -1e300;
  m->right.position_base.z = 5e-324;
  m->right.object_name = "";
}

static void fill_body_schema(reflex_msg_BodySchemaChange* m) {
  memset(m, 0, sizeof *m);
  m->segment_name = "gaze_line_7";
  m->operation = reflex_msg_SCHEMA_DETACH;
  m->parent_link = "head_link";
  m->shape = reflex_msg_SHAPE_CAPSULE;
  m->point_a.x = 0.05;
  m->point_a.y = 0.0;
  m->point_a.z = 0.1;
  m->point_b.x = 0.8;
  m->point_b.y = -0.3;
  m->point_b.z = -0.2;
  m->radius = 0.035;
  m->motion_priority = -3 + REFLEX_K;
  m->enabled = false;
  m->virtual_segment = true;
}

#endif /* REFLEX_TESTS_BUS_CYCLONE_SAMPLES_H */
