/* bus_cyclone_writer: a Cyclone DDS (C) writer of Reflex topics, built from the same idl/ files with
 * Cyclone's idlc. Publishes the C coding of the test sample (cyclone_samples.h) of each selected type
 * every --period-ms, stamped (source "cyclone_writer", seq from 1, system-clock time), until SIGINT
 * or SIGTERM (exit 0, prints "stopped by signal N") or --max-seconds (exit 2). Prints "running". */
#include <signal.h>

#include "cyclone_common.h"

static const char* kHelp =
    "Usage: bus_cyclone_writer --domain N [--types a,b] [--period-ms P] [--max-seconds S]\n"
    "Publish the Reflex test samples with Cyclone DDS until SIGINT/SIGTERM.\n";

static volatile sig_atomic_t g_signal = 0;
static void on_signal(int s) { g_signal = s; }

int main(int argc, char** argv) {
  reflex_args_t a = {0, {0}, "", 30.0, 20};
  const int parsed = reflex_parse_args(argc, argv, &a, kHelp);
  if (parsed != 0) return parsed == 2 ? 0 : 1;

  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);

  const dds_entity_t participant = dds_create_participant((dds_domainid_t)a.domain, NULL, NULL);
  if (participant < 0) {
    fprintf(stderr, "bus_cyclone_writer: dds_create_participant(domain %ld): %s\n", a.domain,
            dds_strretcode(-participant));
    return 1;
  }
  dds_entity_t writers[REFLEX_NUM_TYPES] = {0};
  void* samples[REFLEX_NUM_TYPES] = {NULL};
  for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) {
    if (!a.selected[i]) continue;
    const reflex_type_t* t = &reflex_types[i];
    const dds_entity_t topic = dds_create_topic(participant, t->desc, t->topic, NULL, NULL);
    dds_qos_t* q = reflex_qos(t);
    writers[i] = topic < 0 ? topic : dds_create_writer(participant, topic, q, NULL);
    dds_delete_qos(q);
    if (writers[i] < 0) {
      fprintf(stderr, "bus_cyclone_writer: cannot create the writer of topic '%s': %s\n", t->topic,
              dds_strretcode(-writers[i]));
      dds_delete(participant);
      return 1;
    }
    samples[i] = calloc(1, t->size);
    t->fill(samples[i]);
  }
  printf("running\n");
  fflush(stdout);

  uint64_t seq = 0;
  const int64_t end = reflex_now_ns() + (int64_t)(a.seconds * 1e9);
  int code = 0;
  while (!g_signal) {
    if (reflex_now_ns() >= end) {
      fprintf(stderr, "bus_cyclone_writer: not stopped by a signal within --max-seconds %.1f\n", a.seconds);
      code = 2;
      break;
    }
    ++seq;
    for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) {
      if (samples[i] == NULL) continue;
      /* Every Reflex type starts with its Header. */
      struct reflex_msg_Header* h = (struct reflex_msg_Header*)samples[i];
      h->stamp_ns = reflex_now_ns();
      h->seq = seq;
      h->source = (char*)"cyclone_writer";
      const dds_return_t rc = dds_write(writers[i], samples[i]);
      if (rc < 0) fprintf(stderr, "bus_cyclone_writer: dds_write(%s): %s\n", reflex_types[i].name, dds_strretcode(-rc));
    }
    reflex_sleep_ms(a.period_ms);
  }
  if (code == 0) printf("stopped by signal %d\n", (int)g_signal);
  dds_delete(participant);
  for (size_t i = 0; i < REFLEX_NUM_TYPES; ++i) free(samples[i]);
  return code;
}
