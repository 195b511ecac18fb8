/* bus_cyclone_reader: a Cyclone DDS (C) reader of Reflex topics, built from the same idl/ files with
 * Cyclone's idlc. Waits for one sample of each selected type and checks every field against the C
 * coding of the test sample (cyclone_samples.h). Exit 0 when all arrived intact, 1 otherwise. */
#include "cyclone_common.h"

static const char* kHelp =
    "Usage: bus_cyclone_reader --domain N [--types a,b] [--expect-source NAME] [--timeout-s S]\n"
    "Receive one sample of each type (default: joint_state,control_status,hand_targets,body_schema)\n"
    "with Cyclone DDS and verify it field by field. Exit 0 if all arrived intact.\n";

int main(int argc, char** argv) {
  reflex_args_t a = {0, {0}, "two_process_pub", 15.0, 20};
  const int parsed = reflex_parse_args(argc, argv, &a, kHelp);
  if (parsed != 0) return parsed == 2 ? 0 : 1;

  const dds_entity_t participant = dds_create_participant((dds_domainid_t)a.domain, NULL, NULL);
  if (participant < 0) {
    fprintf(stderr, "bus_cyclone_reader: dds_create_participant(domain %ld): %s\n", a.domain,
            dds_strretcode(-participant));
    return 1;
  }
  dds_entity_t readers[REFLEX_NUM_TYPES] = {0};
  int pending = 0;
  for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) {
    if (!a.selected[i]) continue;
    const reflex_type_t* t = &reflex_types[i];
    const dds_entity_t topic = dds_create_topic(participant, t->desc, t->topic, NULL, NULL);
    dds_qos_t* q = reflex_qos(t);
    readers[i] = topic < 0 ? topic : dds_create_reader(participant, topic, q, NULL);
    dds_delete_qos(q);
    if (readers[i] < 0) {
      fprintf(stderr, "bus_cyclone_reader: cannot create the reader of topic '%s': %s\n", t->topic,
              dds_strretcode(-readers[i]));
      dds_delete(participant);
      return 1;
    }
    ++pending;
  }

  int failures = 0;
  const int64_t end = reflex_now_ns() + (int64_t)(a.seconds * 1e9);
  while (pending > 0 && reflex_now_ns() < end) {
    for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) {
      const dds_entity_t reader = readers[i];
      if (reader <= 0) continue;
      void* buf[1] = {NULL};
      dds_sample_info_t info;
      const dds_return_t n = dds_take(reader, buf, &info, 1, 1);
      if (n <= 0) continue;
      if (info.valid_data) {
        const int diffs = reflex_types[i].check(buf[0], a.source);
        if (diffs == 0) {
          printf("verified %s (seq %llu)\n", reflex_types[i].name,
                 (unsigned long long)((const struct reflex_msg_Header*)buf[0])->seq);
        } else {
          fprintf(stderr, "bus_cyclone_reader: %s: %d field(s) differ\n", reflex_types[i].name, diffs);
          ++failures;
        }
        readers[i] = 0; /* done with this type */
        --pending;
      }
      dds_return_loan(reader, buf, n);
    }
    fflush(stdout);
    reflex_sleep_ms(10);
  }
  if (pending > 0) {
    fprintf(stderr, "bus_cyclone_reader: timed out after %.1f s; never received:", a.seconds);
    for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) {
      if (readers[i] > 0) fprintf(stderr, " %s", reflex_types[i].name);
    }
    fprintf(stderr, "\n");
  }
  dds_delete(participant);
  return (pending == 0 && failures == 0) ? 0 : 1;
}
