#!/usr/bin/python3
"""Report of a flagship run (run_flagship.py): plots like the paper's Figs. 12-13 and the outcome.

Usage: report.py OUT_DIR [--session DIR] [--build DIR]
Reads OUT_DIR/avoidance/controller.csv and OUT_DIR/no_avoidance/controller.csv (either may be
missing) and writes into OUT_DIR:
  fig13_status_distance.png  hand status and arm-to-arm distance with the zone boundaries (Fig. 13)
  blending.png               f(d) of both arms
  tracking.png               hand targets against hand positions
  strip.png                  left camera frames above the robot at the same instants (Fig. 12): the
                             robot drawn in 3D by the live view's own renderer (modules/view/web,
                             static mode, headless Chromium: modules/view/tools/render_scenes.py); if
                             that cannot run, 2D capsules, and the strip's title and report.md say why
  summary.json, report.md    the outcome figures (summary.json's strip_times: the strip's panels' controller
                             times and the closest approach's)
"""
import argparse
import bisect
import csv
import json
import math
import os
import subprocess
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

D_A, D_B, D_R = 0.040, 0.010, 0.005
ORANGE_BOUND = 0.015  # the "within the orange zone" bound for the crossing
HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SHOULDER = {"left": (0.0, 0.23, 1.04), "right": (0.0, -0.23, 1.04)}
REACH = 0.48
# The strip's 3D view (render_scenes.py --camera AZ,EL,RADIUS,TX,TY,TZ): from behind the robot (azimuth pi:
# the camera on -x looking along +x, the robot's own view direction) and 60 deg above, so the arms in
# front of the chest are not hidden by it and left and right are where the camera image has them.
STRIP_CAMERA = "3.1416,1.05,1.45,0.25,0,0.95"


def read(path):
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise SystemExit("report.py: %s has no rows" % path)
    cols = {}
    for key in rows[0]:
        vals = []
        for r in rows:
            try:
                vals.append(float(r[key]))
            except (TypeError, ValueError):
                vals.append(r[key])
        cols[key] = vals
    return cols


def pct(values, p):
    if not values:
        return float("nan")
    v = sorted(values)
    return v[min(len(v) - 1, int(p * len(v)))]


def summarize(ts):
    n = len(ts["time"])
    arm = ts["arm_distance"]
    out = {
        "duration_s": ts["time"][-1] - ts["time"][0],
        "cycles": n,
        "min_arm_distance_m": min(arm),
        "min_arm_distance_time_s": ts["time"][arm.index(min(arm))],
        "min_distance_all_pairs_m": min(ts["min_distance"]),
        "estop_cycles": sum(1 for e in ts["estop"] if e != 0),
        "time_arm_in_yellow_s": sum(1 for d in arm if d < D_A) * 0.005,
        "time_arm_in_orange_s": sum(1 for d in arm if d < D_B) * 0.005,
        "max_f": max(max(ts["left_f"]), max(ts["right_f"])),
    }
    for side in ("left", "right"):
        given = [s == "given" for s in ts[side + "_status"]]
        out[side + "_given_fraction"] = sum(given) / n
        out[side + "_lost_events"] = sum(1 for k in range(1, n) if given[k - 1] and not given[k])
        # Tracking: samples with a reachable target held for >= 1 s and the arm out of the yellow zone.
        errs, held = [], 0
        for k in range(n):
            held = held + 1 if given[k] else 0
            if held < 200 or ts[side + "_f"][k] > 0.0:
                continue
            tgt = (ts[side + "_target_x"][k], ts[side + "_target_y"][k], ts[side + "_target_z"][k])
            if math.dist(tgt, SHOULDER[side]) > REACH:
                continue
            hand = (ts[side + "_hand_x"][k], ts[side + "_hand_y"][k], ts[side + "_hand_z"][k])
            errs.append(math.dist(hand, tgt))
        out[side + "_tracking_samples"] = len(errs)
        out[side + "_tracking_error_median_m"] = pct(errs, 0.5)
        out[side + "_tracking_error_p90_m"] = pct(errs, 0.9)
    return out


def session_frames(session):
    with open(os.path.join(session, "timestamps.csv")) as fh:
        return [(int(r["frame"]), float(r["stamp"])) for r in csv.DictReader(fh)]


def first_given_time(ts):
    for k, (l, r) in enumerate(zip(ts["left_status"], ts["right_status"])):
        if l == "given" or r == "given":
            return ts["time"][k]
    return ts["time"][0]


def session_offset(ts, run):
    """Controller time [s] of the session's first frame, and how it was found: the first row with a hand
    target (vision sees both objects from the first frame; later by the detection and pointing latency,
    tens of ms), never before run.json's vision_start_wall (the row whose wall_time it is: the vision
    process was started then and needs its start-up, about 1.5 s here, before the first frame).
    (Fitting the targets to the session's ground truth was tried: its error curve is too flat.)"""
    late = first_given_time(ts)
    wall = run.get("vision_start_wall")
    walls = ts.get("wall_time")
    if isinstance(wall, (int, float)) and walls and all(isinstance(w, float) and w > 0 for w in (walls[0], walls[-1])):
        k = bisect.bisect_left(walls, wall)
        if k < len(walls) and ts["time"][k] > late:
            return ts["time"][k], "vision start"
    return late, "first hand target"


def extract_frame(session, stamp, dest):
    """The left image at session time `stamp` (ffmpeg, from the session's left video)."""
    with open(os.path.join(session, "session.yaml")) as fh:
        video = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("left_video:")), "left.mp4")
    cmd = ["ffmpeg", "-loglevel", "error", "-y", "-ss", "%.3f" % max(0.0, stamp), "-i",
           os.path.join(session, video), "-frames:v", "1", dest]
    return subprocess.call(cmd) == 0 and os.path.exists(dest)


def draw_capsules(ax, rows):
    for r in rows:
        a = (float(r["ay"]), float(r["az"]))
        b = (float(r["by"]), float(r["bz"]))
        seg = r["segment"]
        arm = seg[:2] in ("l_", "r_") and any(s in seg for s in ("arm", "hand", "shoulder"))
        color = "tab:blue" if arm and seg.startswith("r_") else ("tab:green" if arm else "silver")
        ax.plot([-a[0], -b[0]], [a[1], b[1]], color=color, lw=float(r["radius"]) * 120, solid_capstyle="round",
                alpha=0.75)
    ax.set_aspect("equal")
    ax.set_xlim(-0.55, 0.55)
    ax.set_ylim(0.3, 1.35)
    ax.set_xticks([])
    ax.set_yticks([])


def load_runs(out):
    """The runs in OUT (avoidance/, no_avoidance/): their time series, summaries, DDS security and plant notes."""
    runs = {}
    for label in ("avoidance", "no_avoidance"):
        path = os.path.join(out, label, "controller.csv")
        if os.path.exists(path):
            runs[label] = read(path)
    if not runs:
        raise SystemExit("report.py: no run in %s (expected avoidance/controller.csv)" % out)
    summary = {label: summarize(ts) for label, ts in runs.items()}
    security = {}  # label -> the --secure folder of run_flagship.py, or None (plain DDS)
    plant = {}     # label -> run.json: "robot" (kinematic | mujoco) and MuJoCo's contact counts
    for label in runs:
        try:
            with open(os.path.join(out, label, "run.json")) as fh:
                note = json.load(fh)
        except (OSError, ValueError):
            note = {}
        security[label] = note.get("secure")
        summary[label]["secure"] = bool(security[label])
        plant[label] = note
        summary[label]["robot"] = note.get("robot", "kinematic")
        if "robot_contact_steps" in note:
            summary[label]["mujoco_contact_steps"] = note["robot_contact_steps"]
            summary[label]["mujoco_contact_periods"] = note.get("robot_contact_periods", 0)

    return runs, summary, security, plant


def plot_figures(out, runs, main_ts):
    """Fig. 13 (hand status, arm-to-arm distance), f(d) and the hands against their targets, as PNGs in OUT."""
    t = main_ts["time"]
    # Fig. 13: hand status and arm-to-arm distance.
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True, gridspec_kw={"height_ratios": [1, 1, 3]})
    for ax, side in zip(axes[:2], ("left", "right")):
        ax.step(t, [1 if s == "given" else 0 for s in main_ts[side + "_status"]], where="post")
        ax.set_yticks([0, 1])
        ax.set_yticklabels(["no target", "given"])
        ax.set_ylabel(side + " hand")
    # The runs thick (with avoidance solid blue on top, without it dashed purple), the zone bounds thin and
    # dotted: no run shares a colour or a line style with a bound.
    style = {"avoidance": ("tab:blue", "-", "with avoidance", 3), "no_avoidance": ("tab:purple", "--", "without avoidance", 2)}
    for label, ts in runs.items():
        color, ls, name, z = style[label]
        axes[2].plot(ts["time"], [min(d, 0.3) * 1000 for d in ts["arm_distance"]], color=color, ls=ls, lw=1.6,
                     zorder=z, label=name)
    for v, c, name in ((D_A, "gold", "yellow zone d_a"), (D_B, "orange", "orange zone d_b"), (D_R, "red", "red zone d_r")):
        axes[2].axhline(v * 1000, color=c, ls=":", lw=1.2, label=name)
    axes[2].axhline(0, color="black", lw=0.8)
    axes[2].set_ylabel("arm-to-arm distance (mm)")
    axes[2].set_xlabel("time (s)")
    axes[2].set_ylim(-100, 300)
    axes[2].legend(fontsize=8, loc="upper right")
    fig.suptitle("Flagship: hand status and the distance between the arms (paper Fig. 13)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig13_status_distance.png"), dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(11, 3.5))
    for side, c in (("left", "tab:green"), ("right", "tab:blue")):
        ax.plot(t, main_ts[side + "_f"], color=c, label=side + " arm f(d)")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("time (s)")
    ax.legend(fontsize=8)
    ax.set_title("blending coefficient f(d) (Eq. 13), with avoidance")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "blending.png"), dpi=90)
    plt.close(fig)

    fig, axes = plt.subplots(3, 2, figsize=(11, 7), sharex=True)
    for col, side in enumerate(("left", "right")):
        for row, a in enumerate("xyz"):
            ax = axes[row][col]
            ax.plot(t, main_ts["%s_target_%s" % (side, a)], ls="--", color="gray", label="target (pointing)")
            ax.plot(t, main_ts["%s_hand_%s" % (side, a)], label="hand")
            ax.set_ylabel("%s %s (m)" % (side, a))
        axes[0][col].set_title(side + " hand")
    axes[0][1].legend(fontsize=8)
    fig.suptitle("hand targets from the pointing module against the hands (with avoidance)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "tracking.png"), dpi=90)
    plt.close(fig)



def make_strip(args, main_label, main_ts):
    """The frame strip: the camera image above the robot at key instants inside the session's video.
    (whether it was made, how the robot is drawn: "3d" or "2d: <why the 3D render did not run>")."""
    t = main_ts["time"]
    # Strip: camera frame above the robot at key instants, all inside the session's video.
    strip_ok = False
    strip_robot = None  # "3d" or "2d: <why the 3D render did not run>"
    strip_times = {}  # the panels' controller times and the closest approach's (summary.json)
    try:
        try:
            with open(os.path.join(args.out, main_label, "run.json")) as fh:
                run_info = json.load(fh)
        except (OSError, ValueError):
            run_info = {}
        rate = float(run_info.get("rate", 1.0)) or 1.0
        offset, synced_by = session_offset(main_ts, run_info)  # controller time of the session's first frame
        frames = session_frames(args.session)
        # Controller time of session stamp s: offset + (s - first stamp) / rate. The last pick is the last
        # frame of the video (the controller keeps running a little after it: no picture there).
        video_end = offset + (frames[-1][1] - frames[0][1]) / rate
        in_video = [k for k in range(len(t)) if offset <= t[k] <= video_end]
        if not in_video:
            raise ValueError("no controller row during the session's video (%.1f..%.1f s)" % (offset, video_end))
        first, last = in_video[0], in_video[-1]
        arm = main_ts["arm_distance"]
        k_min = min(in_video, key=lambda k: arm[k])
        lost = next((k for k in range(first + 1, last + 1) if main_ts["left_status"][k] != "given" and main_ts["left_status"][k - 1] == "given"), None)
        # Four different moments, never the same one twice: both hands reaching (3 s in), a target lost,
        # the arms entering the yellow zone on their way to the closest approach, the closest approach.
        # (The end of the video was a fifth pick; it is usually the same crossing as the closest approach.)
        picks = [min(last, first + int(3.0 / 0.005))]
        if lost is not None:
            picks.append(min(last, lost + 200))
        approach = next((k for k in range(k_min, first - 1, -1) if arm[k] >= D_A), None)
        if approach is not None and t[k_min] - t[approach] >= 2.0:
            picks.append(approach)
        else:  # no approach 2 s long: 2 s before the closest approach
            picks.append(max(first, k_min - int(2.0 / 0.005)))
        picks.append(k_min)
        kept = []
        for k in sorted(set(picks)):  # at least 2 s apart
            if not kept or t[k] - t[kept[-1]] >= 2.0:
                kept.append(k)
            elif k == k_min:  # the closest approach wins over a pick too close before it
                kept[-1] = k
        picks = kept
        times = [t[k] for k in picks]
        strip_times = {"panels_s": [round(x, 3) for x in times], "closest_approach_s": round(t[k_min], 3)}
        tmp = os.path.join(args.out, "strip")
        os.makedirs(tmp, exist_ok=True)
        log_csv = os.path.join(args.out, main_label, "controller.csv")
        render = subprocess.run([sys.executable, os.path.join(ROOT, "modules", "view", "tools", "render_scenes.py"),
                                 "--log", log_csv, "--at", ",".join("%.4f" % x for x in times), "--out", tmp,
                                 "--tile", "320x380", "--build", args.build, "--camera", STRIP_CAMERA],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        tiles = []
        if render.returncode == 0:
            with open(os.path.join(tmp, "render.json")) as fh:
                tiles = [tile["png"] for tile in json.load(fh)["tiles"]]
            strip_robot = "3d"
        else:
            lines = render.stdout.strip().splitlines()
            strip_robot = "2d: " + (lines[-1] if lines else "render_scenes.py exit %d" % render.returncode)
            print("report.py: warning: the strip's robot is NOT drawn in 3D (%s); drawing 2D capsules instead"
                  % strip_robot[4:], file=sys.stderr)
            sim = os.path.join(args.build, "bin", "reflex_sim")
            subprocess.check_call([sim, "--postures-from", log_csv, "--at", ",".join("%.4f" % x for x in times),
                                   "--out", tmp], stdout=subprocess.DEVNULL)
            with open(os.path.join(tmp, "postures.csv")) as fh:
                prow = list(csv.DictReader(fh))
        fig, axes = plt.subplots(2, len(times), figsize=(3.2 * len(times), 7.0), squeeze=False,
                                 gridspec_kw={"height_ratios": [3, 4]})
        for i, tt in enumerate(times):
            st = (tt - offset) * rate + frames[0][1]
            img = os.path.join(tmp, "frame_%d.png" % i)
            if extract_frame(args.session, min(st, frames[-1][1]), img):
                axes[0][i].imshow(mpimg.imread(img))
            else:  # never a silently empty panel
                print("report.py: warning: no camera frame at session time %.2f s (ffmpeg)" % st, file=sys.stderr)
                axes[0][i].text(0.5, 0.5, "no camera frame\nat session t = %.1f s" % st, ha="center", va="center",
                                color="red", transform=axes[0][i].transAxes)
            axes[0][i].set_title("t = %.1f s, d_arms = %.0f mm" % (tt, main_ts["arm_distance"][picks[i]] * 1000), fontsize=8)
            axes[0][i].axis("off")
            if tiles:
                axes[1][i].imshow(mpimg.imread(tiles[i]))
                axes[1][i].axis("off")
            else:
                draw_capsules(axes[1][i], [r for r in prow if int(r["frame"]) == i])
        if tiles:
            fig.suptitle("camera (left image) and the robot as the live view draws it, seen from behind and above, "
                         "looking where its cameras look (its left arm on the image's left, as in the camera image)\n"
                         "capsules coloured by zone: green free, yellow, orange, red; grey not in an arm's closest "
                         "pair; white bars: each arm's closest pair\n"
                         "camera frame at controller time t: session start %.2f s, from the %s" % (offset, synced_by),
                         fontsize=9)
        else:
            axes[1][0].set_ylabel("robot (from behind: its left on the left)")
            fig.suptitle("camera (left image) and the robot's collision capsules (right arm blue, left arm green)\n"
                         "2D: the 3D render did not run: %s" % strip_robot[4:], fontsize=9, color="darkred")
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "strip.png"), dpi=80)
        plt.close(fig)
        strip_ok = True
    except (subprocess.CalledProcessError, OSError, ValueError, KeyError, IndexError) as e:
        print("report.py: warning: no frame strip: %s" % e, file=sys.stderr)
    return strip_ok, strip_robot, strip_times


def write_report(args, summary, security, plant, strip_ok, strip_robot):
    """summary.json and report.md in OUT."""
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    lines = ["# Flagship experiment report", "",
             "Session `%s` replayed through reflex_vision -> reflex_behavior -> reflex_controller over DDS." % args.session,
             "", "| | with avoidance | without avoidance |", "| --- | --- | --- |"]
    def mode(label):
        if label not in security:
            return "-"
        return "secure (DDS-Security, identities from `%s`)" % security[label] if security[label] else "plain"
    lines.append("| DDS | %s | %s |" % (mode("avoidance"), mode("no_avoidance")))
    def robot(label):
        if label not in plant:
            return "-"
        if plant[label].get("robot") == "mujoco":
            return "mujoco (reflex_mujoco over DDS, the controller with --robot dds; distances from the measured state)"
        return "kinematic (the controller's in-process plant)"
    lines.append("| robot | %s | %s |" % (robot("avoidance"), robot("no_avoidance")))
    def startup(label):
        if label not in plant:
            return "-"
        failures = plant[label].get("startup_failures", [])
        waited = plant[label].get("startup_s")
        text = ("connected after %.1f s" % waited) if isinstance(waited, (int, float)) else "-"
        if failures:
            text += ", at attempt %d (the chain was started again after: %s)" % (
                len(failures) + 1, "; ".join(f.replace("|", "/") for f in failures))
        return text
    lines.append("| start-up | %s | %s |" % (startup("avoidance"), startup("no_avoidance")))
    on, off = summary.get("avoidance", {}), summary.get("no_avoidance", {})
    def cell(d, key, scale=1.0, fmt="%.1f"):
        return (fmt % (d[key] * scale)) if key in d else "-"
    for key, name, scale, fmt in (("min_arm_distance_m", "closest arm-to-arm distance (mm)", 1000, "%.1f"),
                                  ("min_arm_distance_time_s", "... at (s)", 1, "%.1f"),
                                  ("min_distance_all_pairs_m", "closest pair of all (mm)", 1000, "%.1f"),
                                  ("time_arm_in_yellow_s", "arms in the yellow zone (s)", 1, "%.1f"),
                                  ("time_arm_in_orange_s", "arms in the orange zone (s)", 1, "%.2f"),
                                  ("estop_cycles", "cycles with the e-stop latched", 1, "%d"),
                                  ("max_f", "max f(d)", 1, "%.2f"),
                                  ("left_lost_events", "left target lost (events)", 1, "%d"),
                                  ("right_lost_events", "right target lost (events)", 1, "%d"),
                                  ("left_tracking_error_median_m", "left hand tracking error, median (mm)", 1000, "%.1f"),
                                  ("right_tracking_error_median_m", "right hand tracking error, median (mm)", 1000, "%.1f"),
                                  ("mujoco_contact_steps", "MuJoCo contact steps (pairs closer than d_r)", 1, "%d")):
        if key == "mujoco_contact_steps" and key not in on and key not in off:
            continue  # the kinematic plant has no judge
        lines.append("| %s | %s | %s |" % (name, cell(on, key, scale, fmt), cell(off, key, scale, fmt)))
    lines += ["", "![Fig. 13](fig13_status_distance.png)", "", "![f(d)](blending.png)", "", "![tracking](tracking.png)"]
    if strip_ok:
        lines += ["", "![strip](strip.png)"]
        if strip_robot != "3d":
            lines += ["", "**The strip draws the robot as 2D capsules: the 3D render (the live view's renderer in "
                          "headless Chromium) did not run: %s**" % strip_robot[4:]]
    with open(os.path.join(args.out, "report.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines[4:4 + 16]))
    print("report.py: wrote %s/report.md and plots" % args.out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--session", default=os.path.join(ROOT, "bringup", "sessions", "flagship"))
    ap.add_argument("--build", default=os.environ.get("REFLEX_BUILD_DIR", os.path.join(ROOT, "build")))
    args = ap.parse_args()
    runs, summary, security, plant = load_runs(args.out)
    main_label = "avoidance" if "avoidance" in runs else next(iter(runs))
    main_ts = runs[main_label]
    plot_figures(args.out, runs, main_ts)
    strip_ok, strip_robot, strip_times = make_strip(args, main_label, main_ts)
    summary["strip_robot"] = strip_robot or "none"
    summary["strip_times"] = strip_times
    write_report(args, summary, security, plant, strip_ok, strip_robot)
    return 0

if __name__ == "__main__":
    sys.exit(main())
