/* ros2_cyclone_robot: a ros2_control robot as ROS 2 puts it on DDS, written with Cyclone DDS (the C
 * API; types from idl/ros2.idl by Cyclone's idlc), for ros2_wire_test. Written from the published
 * facts only (ROS 2's topic and type naming, its default QoS), nothing of Reflex.
 *
 * Publishes sensor_msgs/JointState on rt/joint_states every 5 ms (ROS 2 default QoS: reliable,
 * volatile, keep last 10), stamped with the system clock: every joint given with --q NAME=VALUE, plus
 * a joint the robot model does not have (gripper_joint). The joints of the forward controller
 * (--joints A,B,...) follow the last command received, as a position interface does.
 * Subscribes with the same QoS to the controller's command: --command forward reads
 * std_msgs/Float64MultiArray on rt/<controller>/commands, trajectory reads
 * trajectory_msgs/JointTrajectory on rt/<controller>/joint_trajectory.
 * Schedule (seconds from when its command reader matched the controller's writer, plus 300 ms):
 * good states until --bad-at; then 2 states with --rename's joint
 * renamed (the model's joint missing), 1 with one position too few, 1 naming a joint twice, 1 with a
 * NaN position, 1 stamped 1 s ahead; then 40 states stamped 0 (a driver that does not stamp) and
 * 40 without velocities; then good states until --stop-at; then it listens until --listen-until.
 * Prints (stdout):
 *   sent good G missing M length L duplicate D nan N future F unstamped U no_velocity V (as sent)
 *   commands N wrong_size S non_finite F wrong_names W wrong_points P first_s A max_step_rad M
 *   final NAME=VALUE ... (each commanded joint's last position)
 * Exit 0 when it ran (the test judges), 1 on a set-up error. */
#include <dds/dds.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "support/mono_clock.h"
#include "ros2.h"

typedef sensor_msgs_msg_dds__JointState_ JointState;
typedef std_msgs_msg_dds__Float64MultiArray_ Float64MultiArray;
typedef trajectory_msgs_msg_dds__JointTrajectory_ JointTrajectory;

#define MAX_JOINTS 64

static const char* kHelp =
    "Usage: ros2_cyclone_robot --domain N --q NAME=VALUE ... --joints A,B,... [--command forward|trajectory]\n"
    "                          [--controller NAME] [--rename JOINT] [--bad-at S] [--stop-at S] [--listen-until S]\n"
    "A ros2_control robot on DDS with Cyclone: rt/joint_states out, the controller's command in.\n";

static char* names[MAX_JOINTS + 1];
static double q[MAX_JOINTS + 1];
static int nq = 0;
static char* cmd_names[MAX_JOINTS];
static int cmd_index[MAX_JOINTS];
static int ncmd = 0;

static int find_joint(const char* name) {
  for (int i = 0; i < nq; ++i)
    if (strcmp(names[i], name) == 0) return i;
  return -1;
}

int main(int argc, char** argv) {
  long domain = -1;
  double bad_at = 2.0, stop_at = 5.0, listen_until = 6.0;
  const char* command = "forward";
  const char* controller = NULL;
  const char* rename = NULL;
  char* joints_arg = NULL;
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const char* v = i + 1 < argc ? argv[i + 1] : NULL;
    if (strcmp(a, "--help") == 0) {
      fputs(kHelp, stdout);
      return 0;
    }
    if (v == NULL) {
      fprintf(stderr, "ros2_cyclone_robot: %s needs a value\n%s", a, kHelp);
      return 1;
    }
    ++i;
    if (strcmp(a, "--domain") == 0)
      domain = strtol(v, NULL, 10);
    else if (strcmp(a, "--bad-at") == 0)
      bad_at = atof(v);
    else if (strcmp(a, "--stop-at") == 0)
      stop_at = atof(v);
    else if (strcmp(a, "--listen-until") == 0)
      listen_until = atof(v);
    else if (strcmp(a, "--command") == 0)
      command = v;
    else if (strcmp(a, "--controller") == 0)
      controller = v;
    else if (strcmp(a, "--rename") == 0)
      rename = v;
    else if (strcmp(a, "--joints") == 0)
      joints_arg = strdup(v);
    else if (strcmp(a, "--q") == 0) {
      const char* eq = strchr(v, '=');
      if (eq == NULL || nq >= MAX_JOINTS) {
        fprintf(stderr, "ros2_cyclone_robot: --q %s: expected NAME=VALUE\n", v);
        return 1;
      }
      names[nq] = strndup(v, (size_t)(eq - v));
      q[nq++] = atof(eq + 1);
    } else {
      fprintf(stderr, "ros2_cyclone_robot: unknown option %s\n%s", a, kHelp);
      return 1;
    }
  }
  const int trajectory = strcmp(command, "trajectory") == 0;
  if (domain < 0 || nq == 0 || joints_arg == NULL || (!trajectory && strcmp(command, "forward") != 0)) {
    fprintf(stderr, "ros2_cyclone_robot: --domain, --q, --joints and a known --command are required\n%s", kHelp);
    return 1;
  }
  for (char* tok = strtok(joints_arg, ","); tok != NULL && ncmd < MAX_JOINTS; tok = strtok(NULL, ",")) {
    cmd_names[ncmd] = tok;
    cmd_index[ncmd] = find_joint(tok);
    if (cmd_index[ncmd] < 0) {
      fprintf(stderr, "ros2_cyclone_robot: --joints names '%s', which --q does not give\n", tok);
      return 1;
    }
    ++ncmd;
  }
  names[nq] = "gripper_joint"; /* a joint the robot model does not have */
  q[nq] = 0.01;
  const int nsent = nq + 1;
  if (controller == NULL) controller = trajectory ? "joint_trajectory_controller" : "forward_position_controller";
  char cmd_topic[256];
  snprintf(cmd_topic, sizeof(cmd_topic), "rt/%s/%s", controller, trajectory ? "joint_trajectory" : "commands");

  const dds_entity_t participant = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
  if (participant < 0) {
    fprintf(stderr, "ros2_cyclone_robot: dds_create_participant: %s\n", dds_strretcode(-participant));
    return 1;
  }
  /* ROS 2's default QoS (rmw_qos_profile_default): reliable, volatile, keep last 10. */
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(qos, DDS_DURABILITY_VOLATILE);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  const dds_entity_t state_topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__JointState__desc, "rt/joint_states", NULL, NULL);
  const dds_entity_t command_topic =
      trajectory ? dds_create_topic(participant, &trajectory_msgs_msg_dds__JointTrajectory__desc, cmd_topic, NULL, NULL)
                 : dds_create_topic(participant, &std_msgs_msg_dds__Float64MultiArray__desc, cmd_topic, NULL, NULL);
  if (state_topic < 0 || command_topic < 0) {
    fprintf(stderr, "ros2_cyclone_robot: dds_create_topic failed\n");
    return 1;
  }
  const dds_entity_t writer = dds_create_writer(participant, state_topic, qos, NULL);
  const dds_entity_t reader = dds_create_reader(participant, command_topic, qos, NULL);
  dds_delete_qos(qos);
  if (writer < 0 || reader < 0) {
    fprintf(stderr, "ros2_cyclone_robot: creating the writer / reader failed\n");
    return 1;
  }

  /* No state before the command reader has matched the controller's writer (up to 15 s), and 300 ms
   * more for the controller's writer to match this reader: the controller commands as soon as a state
   * arrives, and a command written before both ends know each other reaches nobody (volatile), so the
   * test's "every command sent arrived" would depend on discovery's timing (it took 1 s once). */
  for (const double until = mono_now_s() + 15.0; mono_now_s() < until;) {
    dds_subscription_matched_status_t matched;
    if (dds_get_subscription_matched_status(reader, &matched) == DDS_RETCODE_OK && matched.current_count > 0) break;
    dds_sleepfor(DDS_MSECS(10));
  }
  dds_sleepfor(DDS_MSECS(300));

  double pos[MAX_JOINTS + 1], vel[MAX_JOINTS + 1];
  char* sent_names[MAX_JOINTS + 2];
  long good = 0, unstamped = 0, no_velocity = 0;
  long bad[6] = {0, 0, 0, 0, 0, 0}; /* renamed (2), short, duplicate, NaN, future */
  int phase = 0;                    /* 0 good, 1 bad ones done */
  long commands = 0, wrong_size = 0, non_finite = 0, wrong_names = 0, wrong_points = 0;
  double first_s = -1, max_step = 0, last_cmd[MAX_JOINTS];
  int have_cmd = 0;
  const double t0 = mono_now_s();
  double next = t0;
  void* samples[1] = {NULL};
  dds_sample_info_t infos[1];
  Float64MultiArray fwd;
  JointTrajectory traj;
  memset(&fwd, 0, sizeof(fwd));
  memset(&traj, 0, sizeof(traj));
  samples[0] = trajectory ? (void*)&traj : (void*)&fwd;
  for (;;) {
    const double now = mono_now_s() - t0;
    if (now >= listen_until) break;
    /* Commands: check each, and move the commanded joints there. */
    while (dds_take(reader, samples, infos, 1, 1) > 0) {
      if (!infos[0].valid_data) continue;
      ++commands;
      if (first_s < 0) first_s = now;
      const double* values = NULL;
      uint32_t n = 0;
      if (trajectory) {
        if (traj.points._length != 1 || traj.points._buffer[0].time_from_start.sec != 0 ||
            traj.points._buffer[0].time_from_start.nanosec == 0) {
          ++wrong_points;
          continue;
        }
        int names_ok = traj.joint_names._length == (uint32_t)ncmd;
        for (int k = 0; names_ok && k < ncmd; ++k) names_ok = strcmp(traj.joint_names._buffer[k], cmd_names[k]) == 0;
        if (!names_ok) ++wrong_names;
        values = traj.points._buffer[0].positions._buffer;
        n = traj.points._buffer[0].positions._length;
      } else {
        values = fwd.data._buffer;
        n = fwd.data._length;
      }
      if (n != (uint32_t)ncmd) {
        ++wrong_size;
        continue;
      }
      int finite = 1;
      for (int k = 0; k < ncmd; ++k) finite = finite && isfinite(values[k]);
      if (!finite) {
        ++non_finite;
        continue;
      }
      for (int k = 0; k < ncmd; ++k) {
        if (have_cmd && fabs(values[k] - last_cmd[k]) > max_step) max_step = fabs(values[k] - last_cmd[k]);
        last_cmd[k] = values[k];
        q[cmd_index[k]] = values[k];
      }
      have_cmd = 1;
    }
    if (now < stop_at && mono_now_s() >= next) {
      next += 0.005;
      JointState s;
      memset(&s, 0, sizeof(s));
      struct timespec rt;
      clock_gettime(CLOCK_REALTIME, &rt);
      s.header.stamp.sec = (int32_t)rt.tv_sec;
      s.header.stamp.nanosec = (uint32_t)rt.tv_nsec;
      s.header.frame_id = "";
      int n = nsent;
      for (int i = 0; i < n; ++i) {
        sent_names[i] = names[i];
        pos[i] = q[i];
        vel[i] = 0.0;
      }
      int npos = n, nvel = n;
      if (now >= bad_at && phase == 0) {
        /* The bad states, one after the other, each sent once (two of the first). */
        static int step = 0;
        const int r = rename != NULL ? find_joint(rename) : 0;
        switch (step) {
          case 0:
          case 1: sent_names[r] = "renamed_joint"; break; /* the model's joint is missing */
          case 2: npos = n - 1; break;                    /* one position too few */
          case 3: sent_names[1] = sent_names[0]; break;   /* a name listed twice */
          case 4: pos[r] = NAN; break;                    /* NaN */
          case 5: s.header.stamp.sec += 1; break;         /* 1 s ahead */
          default: break;
        }
        ++bad[step < 2 ? 0 : step - 1];
        if (++step >= 6) phase = 1;
      } else if (phase == 1 && unstamped < 40) {
        s.header.stamp.sec = 0;
        s.header.stamp.nanosec = 0;
        ++unstamped;
        if (unstamped == 40) phase = 2;
      } else if (phase == 2 && no_velocity < 40) {
        nvel = 0;
        ++no_velocity;
        if (no_velocity == 40) phase = 3;
      } else {
        ++good;
      }
      s.name._buffer = sent_names;
      s.name._length = s.name._maximum = (uint32_t)n;
      s.position._buffer = pos;
      s.position._length = s.position._maximum = (uint32_t)npos;
      s.velocity._buffer = vel;
      s.velocity._length = s.velocity._maximum = (uint32_t)nvel;
      s.effort._length = s.effort._maximum = 0;
      s.effort._buffer = NULL;
      const dds_return_t rc = dds_write(writer, &s);
      if (rc < 0) fprintf(stderr, "ros2_cyclone_robot: dds_write: %s\n", dds_strretcode(-rc));
    }
    mono_sleep_until(mono_now_s() + 0.0005);
  }
  printf("sent good %ld missing %ld length %ld duplicate %ld nan %ld future %ld unstamped %ld no_velocity %ld\n", good,
         bad[0], bad[1], bad[2], bad[3], bad[4], unstamped, no_velocity);
  printf("commands %ld wrong_size %ld non_finite %ld wrong_names %ld wrong_points %ld first_s %.3f max_step_rad %.6f\n",
         commands, wrong_size, non_finite, wrong_names, wrong_points, first_s, max_step);
  printf("final");
  for (int k = 0; k < ncmd; ++k) printf(" %s=%.6f", cmd_names[k], have_cmd ? last_cmd[k] : NAN);
  printf("\n");
  dds_delete(participant);
  return 0;
}
