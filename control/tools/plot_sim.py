#!/usr/bin/env python3
"""Plots a reflex_sim run like the paper's figures.

Usage: reflex_plot_sim.py DIR [SCENARIO]
Reads DIR/timeseries.csv (and DIR/timeseries_3dof.csv, DIR/postures.csv when present) and writes
DIR/distance_f.png   f(d) and closest distance per arm with the zone boundaries (Figs. 5c, 9, 13)
DIR/joints.png       the arm joint angles (Figs. 5c, 9)
DIR/hands.png        hand positions against targets and the trajectory reference (Figs. 7a, 8)
DIR/postures.png     the robot's capsules at six instants, side and front views (Figs. 5, 6, 10, 11)
DIR/one_vs_three_dof.png  hand x, y, z with 1-DOF and 3-DOF avoidance (Fig. 8), when both exist
"""
import csv
import math
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

D_A, D_B, D_R = 0.040, 0.010, 0.005


def read(path):
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    cols = {}
    for key in rows[0].keys():
        vals = []
        for r in rows:
            try:
                vals.append(float(r[key]))
            except ValueError:
                vals.append(r[key])
        cols[key] = vals
    return cols


def clip(v, hi=0.2):
    return [min(x, hi) if isinstance(x, float) else x for x in v]


def plot_distance_f(out, title, ts, t):
    """f(d) and the closest distance per arm against the zones: distance_f.png."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 6), sharex=True)
    for col, side in enumerate(("left", "right")):
        axes[0][col].plot(t, ts[side + "_f"], color="tab:red")
        axes[0][col].set_ylim(-0.05, 1.05)
        axes[0][col].set_ylabel("f(d)")
        axes[0][col].set_title(side + " arm")
        d = [x * 1000 for x in clip(ts[side + "_distance"])]
        axes[1][col].plot(t, d, label="closest distance")
        axes[1][col].plot(t, [x * 1000 for x in clip(ts["min_distance"])], color="gray", lw=0.8, label="all pairs")
        if "arm_distance" in ts:
            axes[1][col].plot(t, [x * 1000 for x in clip(ts["arm_distance"])], color="tab:purple", lw=0.8, ls="-.",
                              label="arm to arm")
        for v, c, name in ((D_A, "gold", "d_a yellow"), (D_B, "orange", "d_b orange"), (D_R, "red", "d_r red")):
            axes[1][col].axhline(v * 1000, color=c, ls="--", lw=1, label=name)
        axes[1][col].axhline(0, color="black", lw=0.8)
        axes[1][col].set_ylim(min(-20, min(d) - 5), 150)
        axes[1][col].set_ylabel("distance (mm)")
        axes[1][col].set_xlabel("time (s)")
    axes[1][1].legend(fontsize=7, loc="upper right")
    fig.suptitle(title + ": blending coefficient and closest distance")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "distance_f.png"), dpi=90)
    plt.close(fig)


def plot_joints(out, title, ts, t):
    """The arm joint angles: joints.png."""
    joints = [k for k in ts if k.startswith("q_") and ("shoulder" in k or "elbow" in k or "wrist" in k)]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for ax, pre in zip(axes, ("q_l_", "q_r_")):
        for k in joints:
            if k.startswith(pre):
                ax.plot(t, ts[k], label=k[2:])
        ax.set_ylabel("angle (rad)")
        ax.legend(fontsize=7, ncol=5)
    axes[1].set_xlabel("time (s)")
    fig.suptitle(title + ": arm joint angles")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "joints.png"), dpi=90)
    plt.close(fig)


def plot_hands(out, title, ts, t):
    """Hands, targets and linear trajectories: hands.png."""
    fig, axes = plt.subplots(3, 2, figsize=(11, 7), sharex=True)
    for col, side in enumerate(("left", "right")):
        for row, ax_name in enumerate("xyz"):
            ax = axes[row][col]
            ax.plot(t, ts["%s_hand_%s" % (side, ax_name)], label="hand")
            ax.plot(t, ts["%s_target_%s" % (side, ax_name)], ls="--", label="target")
            ax.plot(t, ts["%s_ref_%s" % (side, ax_name)], ls=":", label="trajectory")
            ax.set_ylabel("%s %s (m)" % (side, ax_name))
        axes[0][col].set_title(side + " hand")
    axes[0][1].legend(fontsize=7)
    axes[2][0].set_xlabel("time (s)")
    axes[2][1].set_xlabel("time (s)")
    fig.suptitle(title + ": hands, targets and linear trajectories")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "hands.png"), dpi=90)
    plt.close(fig)


def plot_one_vs_three_dof(out, title, ts, t):
    """With timeseries_3dof.csv: the right hand with 1-DOF and 3-DOF avoidance (paper Fig. 8)."""
    three = os.path.join(out, "timeseries_3dof.csv")
    if os.path.exists(three):
        ts3 = read(three)
        fig, axes = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
        for row, ax_name in enumerate("xyz"):
            axes[row].plot(t, ts["right_hand_" + ax_name], label="1-DOF avoidance")
            axes[row].plot(ts3["time"], ts3["right_hand_" + ax_name], ls="--", label="3-DOF avoidance")
            axes[row].plot(t, ts["right_target_" + ax_name], color="gray", lw=0.8, label="target")
            axes[row].set_ylabel("right hand %s (m)" % ax_name)
        err1 = [math.dist((a, b, c), (x, y, z)) * 1000 for a, b, c, x, y, z in zip(
            ts["right_hand_x"], ts["right_hand_y"], ts["right_hand_z"], ts["right_target_x"], ts["right_target_y"], ts["right_target_z"])]
        err3 = [math.dist((a, b, c), (x, y, z)) * 1000 for a, b, c, x, y, z in zip(
            ts3["right_hand_x"], ts3["right_hand_y"], ts3["right_hand_z"], ts3["right_target_x"], ts3["right_target_y"], ts3["right_target_z"])]
        axes[3].plot(t, err1, label="1-DOF")
        axes[3].plot(ts3["time"], err3, ls="--", label="3-DOF")
        axes[3].axhline(10, color="gray", ls=":", label="1 cm")
        axes[3].set_ylim(0, 150)
        axes[3].set_ylabel("error (mm)")
        axes[3].set_xlabel("time (s)")
        axes[0].legend(fontsize=7)
        axes[3].legend(fontsize=7)
        fig.suptitle("1-DOF versus 3-DOF collision avoidance (paper Fig. 8)")
        fig.tight_layout()
        fig.savefig(os.path.join(out, "one_vs_three_dof.png"), dpi=90)
        plt.close(fig)


def plot_postures(out, title):
    """With postures.csv: the robot's capsules at the picked rows, from the side and the front."""
    post = os.path.join(out, "postures.csv")
    if os.path.exists(post):
        with open(post) as fh:
            rows = list(csv.DictReader(fh))
        frames = sorted({int(r["frame"]) for r in rows})
        # The view: asimo_like's box (x -0.5..0.6, y -0.55..0.55, z 0..1.4) when the robot fills it;
        # another robot (smaller, or with its root at the pelvis) gets a box around all its frames,
        # and line widths in proportion.
        def extent(keys):
            vals = [float(r[k]) + sgn * float(r["radius"]) for r in rows for k in keys for sgn in (-1, 1)]
            return min(vals), max(vals)
        zlo, zhi = extent(("az", "bz"))
        xlo, xhi = extent(("ax", "bx"))
        ylo, yhi = extent(("ay", "by"))
        if zlo >= -0.01 and zhi <= 1.4 and zhi - zlo > 0.7 and xlo >= -0.5 and xhi <= 0.6 and ylo >= -0.55 and yhi <= 0.55:
            box = ((-0.5, 0.6), (-0.55, 0.55), (0.0, 1.4))
        else:
            pad = 0.05 * (zhi - zlo)
            half = 0.5 * max(xhi - xlo, yhi - ylo) + pad
            box = ((0.5 * (xlo + xhi) - half, 0.5 * (xlo + xhi) + half), (0.5 * (ylo + yhi) - half, 0.5 * (ylo + yhi) + half),
                   (zlo - pad, zhi + pad))
        width_scale = 1.4 / (box[2][1] - box[2][0])
        fig, axes = plt.subplots(2, len(frames), figsize=(2.2 * len(frames), 6.5))
        for i, fr in enumerate(frames):
            sel = [r for r in rows if int(r["frame"]) == fr]
            for view, (u, v, label) in enumerate((("ax", "az", "side (x-z)"), ("ay", "az", "front (y-z)"))):
                ax = axes[view][i] if len(frames) > 1 else axes[view]
                for r in sel:
                    a = (float(r[u]), float(r[v]))
                    b = (float(r[u.replace("a", "b", 1)]), float(r[v.replace("a", "b", 1)]))
                    rad = float(r["radius"])
                    arm = r["segment"][:2] in ("l_", "r_") and any(s in r["segment"] for s in ("arm", "hand", "shoulder"))
                    color = "tab:blue" if arm and r["segment"].startswith("r_") else ("tab:green" if arm else "silver")
                    ax.plot([a[0], b[0]], [a[1], b[1]], color=color, lw=rad * 2 * 72 / 0.9 * 0.9 * width_scale,
                            solid_capstyle="round", alpha=0.7)
                ax.set_aspect("equal")
                ax.set_xlim(*box[view])
                ax.set_ylim(*box[2])
                ax.set_xticks([])
                ax.set_yticks([])
                if view == 0:
                    ax.set_title("t = %.1f s" % float(sel[0]["time"]), fontsize=8)
                if i == 0:
                    ax.set_ylabel(label)
        fig.suptitle(title + ": postures (right arm blue, left arm green)")
        fig.tight_layout()
        fig.savefig(os.path.join(out, "postures.png"), dpi=80)
        plt.close(fig)


def main():
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        return 0 if len(sys.argv) >= 2 else 2
    out = sys.argv[1]
    title = sys.argv[2] if len(sys.argv) > 2 else os.path.basename(out)
    ts = read(os.path.join(out, "timeseries.csv"))
    t = ts["time"]

    plot_distance_f(out, title, ts, t)
    plot_joints(out, title, ts, t)
    plot_hands(out, title, ts, t)
    plot_one_vs_three_dof(out, title, ts, t)
    plot_postures(out, title)
    return 0

if __name__ == "__main__":
    sys.exit(main())
