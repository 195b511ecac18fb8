#!/usr/bin/env python3
"""The flagship experiment (paper Sec. 8.4, Figs. 12-13), end to end over DDS.

A recorded stereo session of a person holding two tagged objects is replayed through
reflex_vision -> reflex_behavior (pointing) -> reflex_controller, as separate processes on one DDS
domain, once with collision avoidance and once without; everything the controller does is logged,
the bus is recorded when reflex_record exists, and report.py turns the runs into out/flagship/report.md
with plots (hand status and arm-to-arm distance as in Fig. 13, f(d), targets against hands, a strip of
camera frames beside the robot's capsules).

Usage: run_flagship.py [--out DIR] [--build DIR] [--domain N] [--rate R] [--only on|off] [--no-report]
"""
import argparse
import json
import os
import signal
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def log(msg):
    print("flagship: " + msg, flush=True)


class Proc:
    def __init__(self, name, argv, logfile):
        self.name = name
        self.argv = argv
        self.log = open(logfile, "w")
        self.p = subprocess.Popen(argv, stdout=self.log, stderr=subprocess.STDOUT)

    def alive(self):
        return self.p.poll() is None

    def stop(self, timeout=5.0):
        if self.alive():
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self.log.close()
        return self.p.returncode


def session_length(session):
    with open(os.path.join(session, "timestamps.csv")) as fh:
        rows = [line.split(",") for line in fh.read().split("\n")[1:] if line.strip()]
    return float(rows[-1][1]) - float(rows[0][1])


def run_once(args, label, avoidance):
    out = os.path.join(args.out, label)
    os.makedirs(out, exist_ok=True)
    bindir = os.path.join(args.build, "bin")
    length = session_length(args.session) / args.rate
    domain = str(args.domain + (0 if avoidance else 1))
    env_note = {"domain": int(domain), "avoidance": avoidance, "rate": args.rate, "session": args.session}
    procs = []
    try:
        ctl = [os.path.join(bindir, "reflex_controller"), "--domain", domain, "--duration", "%.1f" % (length + 6.0),
               "--log", os.path.join(out, "controller.csv")]
        if not avoidance:
            ctl.append("--no-avoidance")
        procs.append(Proc("controller", ctl, os.path.join(out, "controller.log")))
        procs.append(Proc("behavior", [os.path.join(bindir, "reflex_behavior"), "--config", args.behavior,
                                       "--domain", domain], os.path.join(out, "behavior.log")))
        recorder = os.path.join(bindir, "reflex_record")
        if os.path.exists(recorder):
            procs.append(Proc("recorder", [recorder, "record", "--domain", domain, "--output",
                                           os.path.join(out, "bus.rfx")], os.path.join(out, "recorder.log")))
        time.sleep(2.0)  # discovery
        for p in procs:
            if not p.alive():
                raise RuntimeError("%s exited early (see %s)" % (p.name, p.log.name))
        env_note["vision_start_wall"] = time.time()
        vision = Proc("vision", [os.path.join(bindir, "reflex_vision"), "--session", args.session, "--domain", domain,
                                 "--rate", str(args.rate), "--quiet"], os.path.join(out, "vision.log"))
        procs.append(vision)
        t0 = time.time()
        tty = sys.stdout.isatty()
        last_tenth = -1
        while vision.alive():
            time.sleep(1.0)
            done = min(1.0, (time.time() - t0) / max(length, 1e-3))
            if tty:
                print("\rflagship: %s run %3.0f%% (%.0f of %.0f s)" % (label, 100 * done, time.time() - t0, length),
                      end="", flush=True)
            elif int(done * 10) != last_tenth:
                last_tenth = int(done * 10)
                print("flagship: %s run %3.0f%%" % (label, 100 * done), flush=True)
            for p in procs:
                if p is not vision and not p.alive() and p.name != "recorder":
                    raise RuntimeError("%s died during the run (see %s)" % (p.name, p.log.name))
        if tty:
            print("", flush=True)
        if vision.p.returncode != 0:
            raise RuntimeError("vision failed with exit code %d (see %s)" % (vision.p.returncode, vision.log.name))
        time.sleep(1.0)
    finally:
        codes = {}
        for p in reversed(procs):
            codes[p.name] = p.stop()
        env_note["exit_codes"] = codes
        with open(os.path.join(out, "run.json"), "w") as fh:
            json.dump(env_note, fh, indent=2)
    bad = {k: v for k, v in codes.items() if v not in (0, -signal.SIGTERM, 128 + signal.SIGTERM, None)}
    if bad:
        raise RuntimeError("processes ended badly: %s (logs in %s)" % (bad, out))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "flagship"))
    ap.add_argument("--build", default=os.environ.get("REFLEX_BUILD_DIR", os.path.join(ROOT, "build")))
    ap.add_argument("--session", default=os.path.join(ROOT, "bringup", "sessions", "flagship"))
    ap.add_argument("--behavior", default=os.path.join(ROOT, "bringup", "behavior", "pointing.yaml"))
    ap.add_argument("--domain", type=int, default=int(os.environ.get("REFLEX_DOMAIN_ID", "30")))
    ap.add_argument("--rate", type=float, default=1.0, help="session replay speed (1 = real time)")
    ap.add_argument("--only", choices=["on", "off"], help="run only with (on) or without (off) avoidance")
    ap.add_argument("--no-report", action="store_true")
    args = ap.parse_args()
    if not (0 <= args.domain <= 231):
        ap.error("--domain %d: must be in 0..231 (two consecutive ids are used)" % args.domain)
    if not args.rate > 0:
        ap.error("--rate %g: must be positive" % args.rate)
    for path, what in ((args.session, "session folder"), (args.behavior, "behavior configuration")):
        if not os.path.exists(path):
            ap.error("%s %s does not exist" % (what, path))
    for exe in ("reflex_controller", "reflex_behavior", "reflex_vision"):
        if not os.path.exists(os.path.join(args.build, "bin", exe)):
            ap.error("%s not found in %s/bin (build first: bringup/setup.sh)" % (exe, args.build))
    runs = []
    try:
        if args.only in (None, "on"):
            log("run with collision avoidance (domain %d)" % args.domain)
            runs.append(run_once(args, "avoidance", True))
        if args.only in (None, "off"):
            log("run WITHOUT collision avoidance, for comparison (domain %d)" % (args.domain + 1))
            runs.append(run_once(args, "no_avoidance", False))
    except RuntimeError as e:
        log("error: %s" % e)
        return 1
    if not args.no_report:
        python = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable  # needs matplotlib
        return subprocess.call([python, os.path.join(HERE, "report.py"), args.out, "--session", args.session,
                                "--build", args.build])
    return 0


if __name__ == "__main__":
    sys.exit(main())
