#!/usr/bin/env python3
"""bench_mujoco_controller_latency: the latency from the robot's measured-state stamp to the command
that answers it, with the REAL controller: reflex_mujoco (the robot) and
reflex_controller --robot dds, with reflex_behavior (bringup/behavior/scripted.yaml) moving the arms,
as separate processes. Run by hand (not a CTest test); the figures go into control/README.md.

  --hosts one   the three processes on this host, the default profiles (bringup/dds/reflex_profiles.xml:
                shared memory between processes of one host, UDP otherwise)
  --hosts two   two network namespaces made here and joined by one veth pair (10.<domain>.0.1 robot,
                10.<domain>.0.2 controller; nothing on the machine's real interfaces): reflex_mujoco in
                the robot's, the controller and the behavior in the other; DDS over UDP only with
                multicast discovery, as on a LAN (bringup/dds/reflex_profiles_lan.xml). Needs root
                (ip netns add). Both namespaces share this host's clock, so stamps compare directly.
  --hosts both  one, then two (default)

What is measured (reflex_mujoco's exit line; both ends on the robot's clock): for every JointCommand
the robot accepted, its arrival time minus the stamp (Header.stamp_ns) of the RobotState it answers
(JointCommand.state_stamp_ns), p50 and p99 over every command of the run (the first second after
discovery included). The controller answers the
newest state at the start of each 5 ms cycle (at most one robot period old at 1 kHz), and the robot
takes commands once per period, so the figure's resolution is that period (1 ms). The bus-only round
trip, a stand-in answering at once: bench_mujoco_latency --mode immediate. Printed too: the controller's cycle lateness and its robot counters (states, rejected,
commands, stale events), the robot's loop overruns.

Namespaces are named rfxb-<pid>-robot / -controller and always deleted (also those of an earlier run
whose process is gone). Exit 0 when every run produced its figures.
"""
import argparse
import os
import pathlib
import re
import sys
import tempfile
import time

SOURCE = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(SOURCE / "tests" / "system" / "netns"))
from netns_support import Failure, Processes, VethHosts, raise_failure_on_sigterm, remove_stale  # noqa: E402

TAG = "bench_mujoco_controller_latency"
LAN_PROFILES = SOURCE / "bringup" / "dds" / "reflex_profiles_lan.xml"
LATENCY = re.compile(r"command latency p50 (\d+) us p99 (\d+) us over (\d+) commands")
OVERRUNS = re.compile(r"overruns (\d+) \(periods lost (\d+)\), max lateness (\d+) us")
CTL_LATENESS = re.compile(r"lateness p50 (\d+) us p99 (\d+) us max (\d+) us, overruns (\d+)")
CTL_ROBOT = re.compile(r"robot dds: states (\d+) \(rejected (\d+)\), commands (\d+), robot stale events (\d+)")


def run(args, hosts, work):
    """One run; returns a dict of figures. Raises Failure when a process fails or a figure is missing."""
    procs = Processes(work)
    net = VethHosts("rfxb", args.domain, ("robot", "controller")) if hosts == "two" else None
    try:
        env = dict(os.environ, REFLEX_DOMAIN_ID=str(args.domain))
        profiles = []
        if net:
            net.build()
            profiles = ["--profiles", str(LAN_PROFILES)]

        def start(host, argv, log):
            return procs.start((net.exec_prefix(host) if net else []) + argv, f"{hosts}_{log}", env=env)

        dom = ["--domain", str(args.domain)]
        total = args.duration
        robot = start("robot", [f"{args.bin_dir}/reflex_mujoco", *dom, *profiles, "--duration", f"{total:.1f}"],
                      "robot.log")
        start("controller", [f"{args.bin_dir}/reflex_controller", *dom, *profiles, "--robot", "dds",
                             "--duration", f"{total + 5:.1f}"], "controller.log")
        start("controller", [f"{args.bin_dir}/reflex_behavior", "--config",
                             str(SOURCE / "bringup" / "behavior" / "scripted.yaml"), *dom, *profiles], "behavior.log")
        print(f"{TAG}: {hosts} host(s): the robot runs {total:.0f} s", flush=True)
        robot.wait(timeout=total + 60)  # the robot ends itself after --duration, printing its figures
        rcs = procs.stop(timeout=20)
        procs.check_exit_codes(rcs)
    finally:
        procs.close()
        if net:
            net.delete()
    robot_log = (work / f"{hosts}_robot.log").read_text()
    ctl_log = (work / f"{hosts}_controller.log").read_text()
    m = LATENCY.search(robot_log)
    if not m:
        raise Failure(f"no 'command latency' line in {work / (hosts + '_robot.log')}:\n{robot_log[-2000:]}")
    out = {"p50_us": int(m.group(1)), "p99_us": int(m.group(2)), "commands": int(m.group(3))}
    m = OVERRUNS.search(robot_log)
    if m:
        out.update(robot_overruns=int(m.group(1)), robot_periods_lost=int(m.group(2)))
    m = CTL_LATENESS.search(ctl_log)
    if m:
        out.update(ctl_lateness_p50_us=int(m.group(1)), ctl_lateness_p99_us=int(m.group(2)))
    m = CTL_ROBOT.search(ctl_log)
    if m:
        out.update(ctl_states=int(m.group(1)), ctl_rejected=int(m.group(2)), ctl_commands=int(m.group(3)),
                   ctl_stale_events=int(m.group(4)))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin-dir", default=str(SOURCE / "build" / "bin"), help="folder of the Reflex executables")
    ap.add_argument("--domain", type=int, default=197, help="DDS domain id; also the second octet of 10.x (0..232)")
    ap.add_argument("--hosts", choices=["one", "two", "both"], default="both")
    ap.add_argument("--duration", type=float, default=30.0, help="seconds the robot runs (its --duration)")
    ap.add_argument("--work", help="folder for the logs (default: a new temporary folder)")
    args = ap.parse_args()
    if not 0 <= args.domain <= 232:
        ap.error(f"--domain {args.domain} is not in 0..232")
    if not args.duration > 0:
        ap.error(f"--duration {args.duration} must be > 0")
    for exe in ("reflex_mujoco", "reflex_controller", "reflex_behavior"):
        if not os.access(f"{args.bin_dir}/{exe}", os.X_OK):
            ap.error(f"no executable {args.bin_dir}/{exe} (build it, or give --bin-dir)")
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="bench_mujoco_controller_"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"{TAG}: domain {args.domain}, work folder {work}", flush=True)
    runs = ["one", "two"] if args.hosts == "both" else [args.hosts]
    if "two" in runs:
        if os.geteuid() != 0:
            print(f"{TAG}: error: --hosts two needs root (ip netns add)", flush=True)
            return 1
        remove_stale("rfxb")
    raise_failure_on_sigterm()
    try:
        for hosts in runs:
            f = run(args, hosts, work)
            label = "one host (default profiles)" if hosts == "one" else "two network namespaces (veth, UDP, LAN profiles)"
            extra = ", ".join(f"{k} {v}" for k, v in f.items() if k not in ("p50_us", "p99_us", "commands"))
            print(f"{TAG}: {label}: RobotState.stamp -> answering JointCommand at the robot: p50 {f['p50_us']} us, "
                  f"p99 {f['p99_us']} us over {f['commands']} commands ({extra})", flush=True)
    except Failure as e:
        print(f"{TAG}: error: {e}", flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
