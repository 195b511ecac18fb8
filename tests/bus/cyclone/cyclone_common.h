/* Shared parts of the Cyclone DDS interoperability programs: the interop topic types with their
 * topic names, the QoS matching the Reflex profiles (bringup/dds/reflex_profiles.xml), and the
 * command-line parsing. */
#ifndef REFLEX_TESTS_BUS_CYCLONE_COMMON_H
#define REFLEX_TESTS_BUS_CYCLONE_COMMON_H

#include <dds/dds.h>

#include "cyclone_samples.h"

typedef struct {
  const char* name;  /* --types name, as in tests/bus/program_types.hpp */
  const char* topic; /* Reflex topic name (reflex::bus::TopicTraits) */
  const dds_topic_descriptor_t* desc;
  int behavior; /* 1: reflex_behavior profile, 0: reflex_state profile */
  size_t size;
  int (*check)(const void* sample, const char* source);
  void (*fill)(void* sample);
} reflex_type_t;

static int check_joint_state_v(const void* s, const char* src) { return check_joint_state(s, src); }
static int check_control_status_v(const void* s, const char* src) { return check_control_status(s, src); }
static int check_hand_targets_v(const void* s, const char* src) { return check_hand_targets(s, src); }
static int check_body_schema_v(const void* s, const char* src) { return check_body_schema(s, src); }
static void fill_joint_state_v(void* s) { fill_joint_state(s); }
static void fill_control_status_v(void* s) { fill_control_status(s); }
static void fill_hand_targets_v(void* s) { fill_hand_targets(s); }
static void fill_body_schema_v(void* s) { fill_body_schema(s); }

static const reflex_type_t reflex_types[] = {
    {"joint_state", "reflex/joint_state", &reflex_msg_JointState_desc, 0, sizeof(reflex_msg_JointState),
     check_joint_state_v, fill_joint_state_v},
    {"control_status", "reflex/control_status", &reflex_msg_ControlStatus_desc, 0, sizeof(reflex_msg_ControlStatus),
     check_control_status_v, fill_control_status_v},
    {"hand_targets", "reflex/hand_targets", &reflex_msg_HandTargets_desc, 1, sizeof(reflex_msg_HandTargets),
     check_hand_targets_v, fill_hand_targets_v},
    {"body_schema", "reflex/body_schema", &reflex_msg_BodySchemaChange_desc, 1, sizeof(reflex_msg_BodySchemaChange),
     check_body_schema_v, fill_body_schema_v},
};
#define REFLEX_NUM_TYPES (sizeof reflex_types / sizeof reflex_types[0])

/* QoS equivalent to the Reflex profile of the stream. State: best effort, keep last 1, deadline
 * 20 ms (a Fast DDS reader of reflex_state requests 20 ms, so a writer must offer it). Behavior:
 * reliable, transient local, keep last 1. */
static dds_qos_t* reflex_qos(const reflex_type_t* t) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
  if (t->behavior) {
    dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
  } else {
    dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
    dds_qset_deadline(q, DDS_MSECS(20));
  }
  return q;
}

typedef struct {
  long domain;
  int selected[REFLEX_NUM_TYPES];
  const char* source; /* reader: expected Header.source */
  double seconds;     /* reader: timeout; writer: give up after */
  long period_ms;     /* writer */
} reflex_args_t;

/* Parses the common options; returns 0 on success, 1 after printing an error naming the bad value
 * (or 2 after printing the help). */
static int reflex_parse_args(int argc, char** argv, reflex_args_t* a, const char* help) {
  int have_domain = 0;
  for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) a->selected[i] = 1;
  for (int i = 1; i < argc; ++i) {
    const char* opt = argv[i];
    if (strcmp(opt, "-h") == 0 || strcmp(opt, "--help") == 0) {
      fputs(help, stdout);
      return 2;
    }
    if (i + 1 >= argc) {
      fprintf(stderr, "%s: option '%s' needs a value or is unknown (try --help)\n", argv[0], opt);
      return 1;
    }
    const char* val = argv[++i];
    char* end = NULL;
    if (strcmp(opt, "--domain") == 0) {
      a->domain = strtol(val, &end, 10);
      if (*val == '\0' || *end != '\0' || a->domain < 0 || a->domain > 232) {
        fprintf(stderr, "%s: bad --domain '%s' (expected an integer in [0, 232])\n", argv[0], val);
        return 1;
      }
      have_domain = 1;
    } else if (strcmp(opt, "--types") == 0) {
      for (size_t k = 0; k < REFLEX_NUM_TYPES; ++k) a->selected[k] = 0;
      char list[256];
      snprintf(list, sizeof list, "%s", val);
      for (char* tok = strtok(list, ","); tok != NULL; tok = strtok(NULL, ",")) {
        int found = 0;
        for (size_t k = 0; k < REFLEX_NUM_TYPES; ++k) {
          if (strcmp(tok, reflex_types[k].name) == 0) a->selected[k] = found = 1;
        }
        if (!found) {
          fprintf(stderr,
                  "%s: unknown type '%s' in --types (known: joint_state, control_status, "
                  "hand_targets, body_schema)\n",
                  argv[0], tok);
          return 1;
        }
      }
    } else if (strcmp(opt, "--expect-source") == 0) {
      a->source = val;
    } else if (strcmp(opt, "--timeout-s") == 0 || strcmp(opt, "--max-seconds") == 0) {
      a->seconds = strtod(val, &end);
      if (*val == '\0' || *end != '\0' || !(a->seconds > 0)) {
        fprintf(stderr, "%s: bad %s '%s' (expected a positive number)\n", argv[0], opt, val);
        return 1;
      }
    } else if (strcmp(opt, "--period-ms") == 0) {
      a->period_ms = strtol(val, &end, 10);
      if (*val == '\0' || *end != '\0' || a->period_ms < 1 || a->period_ms > 10000) {
        fprintf(stderr, "%s: bad --period-ms '%s' (expected an integer in [1, 10000])\n", argv[0], val);
        return 1;
      }
    } else {
      fprintf(stderr, "%s: unknown option '%s' (try --help)\n", argv[0], opt);
      return 1;
    }
  }
  if (!have_domain) {
    fprintf(stderr, "%s: --domain is required (try --help)\n", argv[0]);
    return 1;
  }
  return 0;
}

static void reflex_sleep_ms(long ms) {
  struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}

#endif /* REFLEX_TESTS_BUS_CYCLONE_COMMON_H */
