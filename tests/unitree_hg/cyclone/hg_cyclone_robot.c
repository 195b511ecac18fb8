/* hg_cyclone_robot: a robot speaking Unitree's hg low-level interface with Cyclone DDS (as Unitree's
 * SDK does), for unitree_hg_cyclone_test. Written from the published facts only (C types from
 * idl/unitree_hg.idl by Cyclone's idlc; its own Crc32Core over its own C structs), nothing of Reflex.
 *
 * Publishes rt/lowstate every 2 ms (500 Hz): tick += 2 per state, crc = Crc32Core over the C struct's
 * first 522 words (padding zeroed), motor q from --q SLOT=VALUE (others 0). The arm_sdk motors follow
 * the last accepted command: q = w * cmd.q + (1 - w) * start q (w = motor_cmd[29].q), as Unitree's
 * robot blends its walking controller with arm_sdk.
 * Schedule (seconds from its start): good states until --bad-at; then 3 states with a wrong crc, 3
 * states repeating the last tick, 2 LowState_ samples of 30 motors (another motor count, same type
 * name), a NaN q and a q 50 rad out on motor 18, 4 valid states from a second DataWriter (another
 * participant), then --stall-ms / 2 states 2 ms apart whose tick stands still (correct crc), then good states until
 * --stop-at; then it only listens until --listen-until.
 * Every rt/arm_sdk LowCmd_ received is checked: crc (its own Crc32Core over the received C struct,
 * padding zeroed), weight, gains, finite values, which slots are commanded.
 * Prints (stdout):
 *   sent good G bad_crc 3 repeat_tick 3 short 2 nan 1 far 1 other_writer 4 stall S
 *   commands N crc_ok N crc_bad B weight_max W weight_last L max_up_step U max_down_step D
 *     longest_gap_ms T gap_start_s A non_finite F out_of_range R
 *   slot I mode M kp KP kd KD   (for every slot of the last command)
 * Exit 0 when it ran (the test judges), 1 on a set-up error. */
#include <dds/dds.h>
#include <dds/ddsc/dds_opcodes.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "support/mono_clock.h"
#include "hg_short.h"
#include "unitree_hg.h"

typedef unitree_hg_msg_dds__LowState_ LowState;
typedef unitree_hg_msg_dds__LowCmd_ LowCmd;

static const char* kHelp =
    "Usage: hg_cyclone_robot --domain N [--q SLOT=VALUE ...] [--bad-at S] [--stall-ms MS] [--stop-at S]\n"
    "                        [--listen-until S]\n"
    "A Unitree hg robot over Cyclone DDS: rt/lowstate out (500 Hz, tick, crc), rt/arm_sdk in (checked).\n";

static uint32_t crc32_core(const uint32_t* words, size_t n) {
  uint32_t crc = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t data = words[i];
    for (int bit = 31; bit >= 0; --bit) {
      const uint32_t top = crc & 0x80000000u, in = (data >> bit) & 1u;
      crc <<= 1;
      if ((top != 0) != (in != 0)) crc ^= 0x04c11db7u;
    }
  }
  return crc;
}

/* Crc32Core over the first sizeof/4 - 1 words of a C struct held in memory. */
static uint32_t struct_crc(const void* p, size_t size) {
  uint32_t words[600];
  memcpy(words, p, size);
  return crc32_core(words, size / 4 - 1);
}

int main(int argc, char** argv) {
  long domain = -1;
  double bad_at = 2.5, stall_ms = 300, stop_at = 6.0, listen_until = 9.0;
  float q0[35] = {0};
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const char* v = i + 1 < argc ? argv[i + 1] : NULL;
    if (strcmp(a, "--help") == 0) {
      fputs(kHelp, stdout);
      return 0;
    } else if (strcmp(a, "--domain") == 0 && v) {
      domain = strtol(v, NULL, 10), ++i;
    } else if (strcmp(a, "--bad-at") == 0 && v) {
      bad_at = atof(v), ++i;
    } else if (strcmp(a, "--stall-ms") == 0 && v) {
      stall_ms = atof(v), ++i;
    } else if (strcmp(a, "--stop-at") == 0 && v) {
      stop_at = atof(v), ++i;
    } else if (strcmp(a, "--listen-until") == 0 && v) {
      listen_until = atof(v), ++i;
    } else if (strcmp(a, "--q") == 0 && v) {
      int slot = -1;
      float value = 0;
      if (sscanf(v, "%d=%f", &slot, &value) != 2 || slot < 0 || slot >= 35 || slot == 29) {
        fprintf(stderr, "hg_cyclone_robot: --q '%s': expected SLOT=VALUE with SLOT in 0..34, not 29\n", v);
        return 1;
      }
      q0[slot] = value, ++i;
    } else {
      fprintf(stderr, "hg_cyclone_robot: unknown or incomplete argument '%s'\n%s", a, kHelp);
      return 1;
    }
  }
  if (domain < 0 || domain > 232) {
    fprintf(stderr, "hg_cyclone_robot: --domain %ld: give 0..232\n", domain);
    return 1;
  }
  const dds_entity_t pp = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
  /* A second participant writes the 30-motor samples (its own topic of the same name and type name),
   * a third one plays a second robot writer (valid states from another DataWriter). */
  const dds_entity_t pp_short = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
  const dds_entity_t pp_other = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
  if (pp < 0 || pp_short < 0 || pp_other < 0) {
    fprintf(stderr, "hg_cyclone_robot: dds_create_participant(%ld) failed\n", domain);
    return 1;
  }
  const dds_entity_t t_state = dds_create_topic(pp, &unitree_hg_msg_dds__LowState__desc, "rt/lowstate", NULL, NULL);
  const dds_entity_t t_cmd = dds_create_topic(pp, &unitree_hg_msg_dds__LowCmd__desc, "rt/arm_sdk", NULL, NULL);
  const dds_topic_descriptor_t* s = &reflex_test_LowStateShort__desc;
  const dds_topic_descriptor_t short_desc = {.m_size = s->m_size,
                                             .m_align = s->m_align,
                                             .m_flagset = s->m_flagset & ~DDS_TOPIC_XTYPES_METADATA,
                                             .m_nkeys = s->m_nkeys,
                                             .m_typename = "unitree_hg::msg::dds_::LowState_",
                                             .m_keys = s->m_keys,
                                             .m_nops = s->m_nops,
                                             .m_ops = s->m_ops,
                                             .m_meta = s->m_meta,
                                             .type_information = {NULL, 0},
                                             .type_mapping = {NULL, 0},
                                             .restrict_data_representation = s->restrict_data_representation};
  const dds_entity_t t_short = dds_create_topic(pp_short, &short_desc, "rt/lowstate", NULL, NULL);
  const dds_entity_t t_other =
      dds_create_topic(pp_other, &unitree_hg_msg_dds__LowState__desc, "rt/lowstate", NULL, NULL);
  if (t_state < 0 || t_cmd < 0 || t_short < 0 || t_other < 0) {
    fprintf(stderr, "hg_cyclone_robot: dds_create_topic failed: %s %s %s\n", dds_strretcode(-t_state),
            dds_strretcode(-t_cmd), dds_strretcode(-t_short));
    return 1;
  }
  dds_qos_t* wq = dds_create_qos();
  dds_qset_reliability(wq, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(wq, DDS_HISTORY_KEEP_LAST, 1);
  dds_qos_t* rq = dds_create_qos();
  dds_qset_reliability(rq, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(rq, DDS_HISTORY_KEEP_LAST, 64);
  const dds_entity_t w_state = dds_create_writer(pp, t_state, wq, NULL);
  const dds_entity_t w_short = dds_create_writer(pp_short, t_short, wq, NULL);
  const dds_entity_t w_other = dds_create_writer(pp_other, t_other, wq, NULL);
  const dds_entity_t r_cmd = dds_create_reader(pp, t_cmd, rq, NULL);
  dds_delete_qos(wq);
  dds_delete_qos(rq);
  if (w_state < 0 || w_short < 0 || w_other < 0 || r_cmd < 0) {
    fprintf(stderr, "hg_cyclone_robot: cannot create the writers / reader\n");
    return 1;
  }

  static LowState state;
  static reflex_test_LowStateShort_ short_state;
  static LowCmd cmd, last;
  int have_last = 0;
  float q[35];
  memcpy(q, q0, sizeof q);
  uint32_t tick = 0;
  long sent_good = 0, sent_bad_crc = 0, sent_repeat = 0, sent_short = 0, sent_stall = 0, sent_other = 0;
  long sent_nan = 0, sent_far = 0;
  long commands = 0, crc_ok = 0, crc_bad = 0, non_finite = 0, out_of_range = 0;
  double weight_max = 0, weight_last = 0, prev_weight = 0, max_up = 0, max_down = 0;
  double last_cmd_t = -1, longest_gap = 0, gap_start = 0;
  const double t0 = mono_now_s();
  double next = t0;
  int phase_done = 0;
  for (;;) {
    next += 0.002;
    mono_sleep_until(next);
    const double t = mono_now_s() - t0;
    if (t >= listen_until) break;
    /* Commands: every one that arrived. */
    for (;;) {
      memset(&cmd, 0, sizeof cmd); /* padding zero, as the SDK's crc needs */
      void* ptrs[1] = {&cmd};
      dds_sample_info_t info;
      if (dds_take(r_cmd, ptrs, &info, 1, 1) <= 0) break;
      if (!info.valid_data) continue;
      ++commands;
      if (struct_crc(&cmd, sizeof cmd) == cmd.crc)
        ++crc_ok;
      else
        ++crc_bad;
      const double w = cmd.motor_cmd[29].q;
      if (!isfinite(w) || w < 0 || w > 1) ++out_of_range;
      for (int k = 0; k < 35; ++k)
        if (!isfinite(cmd.motor_cmd[k].q) || !isfinite(cmd.motor_cmd[k].dq) || !isfinite(cmd.motor_cmd[k].kp) ||
            !isfinite(cmd.motor_cmd[k].kd))
          ++non_finite;
      if (w > weight_max) weight_max = w;
      if (commands > 1) {
        if (w - prev_weight > max_up) max_up = w - prev_weight;
        if (prev_weight - w > max_down) max_down = prev_weight - w;
      } else {
        max_up = w; /* from 0: the first command's weight is its first step */
      }
      prev_weight = weight_last = w;
      const double now = mono_now_s() - t0;
      if (last_cmd_t >= 0 && now - last_cmd_t > longest_gap) {
        longest_gap = now - last_cmd_t;
        gap_start = last_cmd_t;
      }
      last_cmd_t = now;
      last = cmd;
      have_last = 1;
    }
    if (t >= stop_at) continue; /* listening only */
    /* The robot: arm_sdk motors blended by the weight with the start configuration. */
    if (have_last) {
      const float w = last.motor_cmd[29].q;
      for (int k = 12; k <= 28; ++k)
        if (last.motor_cmd[k].mode == 1) q[k] = w * last.motor_cmd[k].q + (1 - w) * q0[k];
    }
    memset(&state, 0, sizeof state);
    for (int k = 0; k < 35; ++k) {
      state.motor_state[k].mode = 1;
      state.motor_state[k].q = q[k];
    }
    state.imu_state.quaternion[0] = 1.0f;
    if (t >= bad_at && !phase_done) {
      phase_done = 1;
      /* 3 wrong crcs (each a new tick), 3 repeats of the last good tick, 2 states of 30 motors. */
      for (int i = 0; i < 3; ++i) {
        state.tick = tick + 2 + (uint32_t)i;
        state.crc = struct_crc(&state, sizeof state) ^ 0x1u;
        dds_write(w_state, &state), ++sent_bad_crc;
        mono_sleep_until(mono_now_s() + 0.002);
      }
      for (int i = 0; i < 3; ++i) {
        state.tick = tick;
        state.crc = struct_crc(&state, sizeof state);
        dds_write(w_state, &state), ++sent_repeat;
        mono_sleep_until(mono_now_s() + 0.002);
      }
      for (int i = 0; i < 2; ++i) {
        memset(&short_state, 0, sizeof short_state);
        short_state.tick = tick + 10 + (uint32_t)i;
        short_state.crc = struct_crc(&short_state, sizeof short_state);
        dds_write(w_short, &short_state), ++sent_short;
        mono_sleep_until(mono_now_s() + 0.002);
      }
      /* A NaN position and one 50 rad out, each with a right crc and a new tick, on motor 18. */
      mono_sleep_until(mono_now_s() + 0.012);
      for (int i = 0; i < 2; ++i) {
        const float keep = state.motor_state[18].q;
        state.motor_state[18].q = i == 0 ? NAN : 50.0f;
        state.tick = tick + 20 + (uint32_t)i;
        state.crc = struct_crc(&state, sizeof state);
        dds_write(w_state, &state);
        if (i == 0)
          ++sent_nan;
        else
          ++sent_far;
        state.motor_state[18].q = keep;
        mono_sleep_until(mono_now_s() + 0.012); /* alone in its control cycle: the controller's line names it */
      }
      /* 4 valid states (crc right, tick ahead) from another DataWriter while this one is alive. */
      for (int i = 0; i < 4; ++i) {
        state.tick = tick + 100 + (uint32_t)i;
        state.crc = struct_crc(&state, sizeof state);
        dds_write(w_other, &state), ++sent_other;
        mono_sleep_until(mono_now_s() + 0.002);
      }
      /* The tick stands still: stall_ms / 2 states with a correct crc, every 2 ms. */
      for (long k = 0; k < (long)(stall_ms / 2); ++k) {
        state.tick = tick;
        state.crc = struct_crc(&state, sizeof state);
        dds_write(w_state, &state), ++sent_stall;
        mono_sleep_until(mono_now_s() + 0.002);
      }
      next = mono_now_s();
      continue;
    }
    tick += 2;
    state.tick = tick;
    state.crc = struct_crc(&state, sizeof state);
    if (dds_write(w_state, &state) >= 0) ++sent_good;
  }
  printf("sent good %ld bad_crc %ld repeat_tick %ld short %ld nan %ld far %ld other_writer %ld stall %ld\n", sent_good,
         sent_bad_crc, sent_repeat, sent_short, sent_nan, sent_far, sent_other, sent_stall);
  printf(
      "commands %ld crc_ok %ld crc_bad %ld weight_max %.6f weight_last %.6f max_up_step %.6f max_down_step %.6f "
      "longest_gap_ms %.1f gap_start_s %.3f non_finite %ld out_of_range %ld\n",
      commands, crc_ok, crc_bad, weight_max, weight_last, max_up, max_down, longest_gap * 1e3, gap_start, non_finite,
      out_of_range);
  if (have_last)
    for (int k = 0; k < 35; ++k)
      printf("slot %d mode %d kp %.3f kd %.3f\n", k, (int)last.motor_cmd[k].mode, (double)last.motor_cmd[k].kp,
             (double)last.motor_cmd[k].kd);
  fflush(stdout);
  dds_delete(pp_other);
  dds_delete(pp_short);
  dds_delete(pp);
  return 0;
}
