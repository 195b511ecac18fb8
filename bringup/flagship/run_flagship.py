#!/usr/bin/env python3
"""The flagship experiment (paper Sec. 8.4, Figs. 12-13), end to end over DDS.

A recorded stereo session of a person holding two tagged objects is replayed through
reflex_vision -> reflex_behavior (pointing) -> reflex_controller, as separate processes on one DDS
domain, once with collision avoidance and once without; everything the controller does is logged,
the bus is recorded when reflex_record exists, and report.py turns the runs into out/flagship/report.md
with plots (hand status and arm-to-arm distance as in Fig. 13, f(d), targets against hands, a strip of
camera frames beside the robot's capsules).

With --secure DIR the same experiment runs with DDS-Security (bringup/security/README.md): every process
gets the complete profiles file of its own identity, DIR/profiles/<module>.xml (reflex_vision: vision,
reflex_behavior: behavior, reflex_controller: controller, reflex_record: recorder), so every participant
authenticates, every topic is access-controlled and encrypted. DIR is made with
bringup/security/make_security.sh when it does not exist or is empty; a folder that exists is used as it
is (it may hold deployed credentials without the CA key) and must hold those four profiles with every
file they name. run.json, summary.json and report.md say which mode ran.

Start-up, either mode: vision starts when reflex_behavior hears the controller's joint states and the
recorder records (under DDS-Security each pair of participants authenticates first, seconds on a loaded
machine), and holds its replay until behavior and recorder matched its writer (reflex_vision
--wait-readers). A link that does not connect in time (--ready-timeout, VISION_WAIT_S) stops the chain
and starts it again, up to STARTUP_ATTEMPTS times; the failed attempt's logs stay as
<name>.attempt<N>.log, and run.json (startup_failures) and report.md name each failure.

With --robot mujoco the robot is the physics-simulated humanoid: reflex_mujoco is started on
the run's domain before the controller, which then runs with --robot dds (it reads the measured state
from reflex/robot_state and commands reflex/joint_command); MuJoCo's contact count (pairs closer than
d_r, from reflex_mujoco's exit line) goes into run.json and the report, which names the plant.
With --robot unitree_hg the same robot speaks Unitree's hg interface (reflex_mujoco --interface
unitree_hg: rt/lowstate, rt/arm_sdk) and the controller runs with --robot unitree_hg (the joint map
beside the URDF; the arm_sdk weight ramps in at start and out when the controller is stopped, before
the robot is).

Usage: run_flagship.py [--out DIR] [--build DIR] [--domain N] [--rate R] [--only on|off] [--secure DIR]
                       [--robot kinematic|mujoco|unitree_hg] [--ready-timeout S] [--no-report]
"""
import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def log(msg):
    print("flagship: " + msg, flush=True)


# The identity (bringup/security/make_security.sh) of each process of the experiment.
SECURE_IDENTITIES = {"controller": "controller", "behavior": "behavior", "recorder": "recorder", "vision": "vision",
                     "view": "view",  # view: reflex_view's read-only identity (subscribe rules only)
                     "robot": "robot"}  # reflex_mujoco: the robot's driver, the one writer of reflex/robot_state
SECURE_READY_TIMEOUT_S = 45.0  # authentication of controller, behavior and recorder (1-5 s per pair, loaded)
READY_TIMEOUT_S = 20.0  # plain discovery (about 1 s)
VISION_WAIT_S = 45.0  # vision holds its replay until behavior (and recorder) matched its writer
STARTUP_ATTEMPTS = 3  # a chain whose link did not connect is stopped and started again, said in log and run.json


class Proc:
    def __init__(self, name, argv, logfile, env=None):
        self.name = name
        self.argv = argv
        self.log = open(logfile, "w")
        self.p = subprocess.Popen(argv, stdout=self.log, stderr=subprocess.STDOUT, env=env)

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


def check_secure_dir(directory):
    """The security folder of --secure: made with make_security.sh when missing or empty, otherwise
    checked (a profiles file per identity, every file:// it names readable). Returns the absolute path;
    raises ValueError with a message naming the folder and what is wrong."""
    directory = os.path.abspath(directory)
    if os.path.exists(directory) and not os.path.isdir(directory):
        raise ValueError("--secure %s: not a folder" % directory)
    if not os.path.exists(directory) or not os.listdir(directory):
        script = os.path.join(ROOT, "bringup", "security", "make_security.sh")
        log("making the security material in %s (%s)" % (directory, os.path.relpath(script, ROOT)))
        r = subprocess.run([script, directory], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if r.returncode != 0:
            raise ValueError("--secure %s: make_security.sh failed (exit %d): %s" % (directory, r.returncode,
                                                                                   r.stdout.strip()))
    for identity in sorted(set(SECURE_IDENTITIES.values())):
        profile = os.path.join(directory, "profiles", identity + ".xml")
        if not os.path.isfile(profile):
            raise ValueError("--secure %s: no profiles/%s.xml (make the material with "
                             "bringup/security/make_security.sh %s)" % (directory, identity, directory))
        with open(profile) as fh:
            text = fh.read()
        if "dds.sec.auth.plugin" not in text:
            raise ValueError("--secure %s: profiles/%s.xml holds no security properties" % (directory, identity))
        for path in re.findall(r"file://([^<\s]+)", text):
            if not os.access(path, os.R_OK):
                raise ValueError("--secure %s: profiles/%s.xml names %s, which is missing or unreadable (folder "
                                 "moved? run bringup/security/make_security.sh %s again)"
                                 % (directory, identity, path, directory))
    return directory


def last_count(path, pattern):
    """The number of the last match of `pattern` (one group) in the log file, or 0."""
    try:
        with open(path, errors="replace") as fh:
            found = re.findall(pattern, fh.read())
    except OSError:
        return 0
    return int(found[-1]) if found else 0


class StartupFailed(RuntimeError):
    """A link of the chain did not connect in time; run_once starts the chain again (STARTUP_ATTEMPTS)."""


def wait_chain_ready(procs, out, secure, timeout):
    """Blocks until the chain before vision is connected: reflex_behavior receives the controller's joint
    states (joint_states=N in its status line, every second) and, when recording, the recorder records
    samples (it matched the controller); then 1 s more for the other pairs (view). Under DDS-Security every
    pair of participants authenticates first: seconds each on a loaded machine. Returns the seconds waited.
    Raises RuntimeError if a process exits, StartupFailed naming the link that did not connect within
    `timeout` seconds."""
    t0 = time.time()
    links = [("behavior", os.path.join(out, "behavior.log"), r"joint_states=(\d+)",
              "reflex_behavior received no joint state from reflex_controller")]
    if any(p.name == "recorder" for p in procs):
        links.append(("recorder", os.path.join(out, "recorder.log"), r"(\d+) samples",
                      "reflex_record recorded nothing (it did not match reflex_controller)"))
    while True:
        missing = [(name, what) for name, path, pattern, what in links if last_count(path, pattern) == 0]
        if not missing:
            break
        for p in procs:
            if not p.alive():
                raise RuntimeError("%s exited during start-up (see %s)" % (p.name, p.log.name))
        if time.time() - t0 > timeout:
            raise StartupFailed("start-up: %s in %.0f s%s (see %s)" % (
                "; ".join(what for _, what in missing), timeout,
                " (authentication failed?)" if secure else "",
                ", ".join(os.path.join(out, name + ".log") for name, _ in missing)))
        time.sleep(0.2)
    time.sleep(1.0)
    log("start-up: %s connected, %.1f s" % ("behavior and recorder" if len(links) > 1 else "behavior",
                                            time.time() - t0))
    return time.time() - t0


def last_line(path, prefix):
    """The last line of the log file that starts with `prefix`, or ''."""
    try:
        with open(path, errors="replace") as fh:
            lines = [line.strip() for line in fh if line.startswith(prefix)]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def session_length(session):
    with open(os.path.join(session, "timestamps.csv")) as fh:
        rows = [line.split(",") for line in fh.read().split("\n")[1:] if line.strip()]
    return float(rows[-1][1]) - float(rows[0][1])


def watch_replay(vision, procs, label, length):
    """Progress while vision replays the session (a line per 10 %, or one updated line on a terminal);
    RuntimeError when another process of the chain dies meanwhile (the recorder and the view may)."""
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
            if p is not vision and not p.alive() and p.name not in ("recorder", "view"):
                raise RuntimeError("%s died during the run (see %s)" % (p.name, p.log.name))
    if tty:
        print("", flush=True)


def stop_chain(args, out, procs, env_note):
    """Stops the chain (last started first) and writes OUT/run.json: the note, every process's exit code
    and, on the physics robot, MuJoCo's judge (physics steps and state periods with a pair closer than
    d_r, from its exit line). The exit codes."""
    codes = {}
    for p in reversed(procs):
        codes[p.name] = p.stop()
    env_note["exit_codes"] = codes
    if args.robot in ("mujoco", "unitree_hg"):
        robot_log = os.path.join(out, "robot.log")
        env_note["robot_contact_steps"] = last_count(robot_log, r"contact steps (\d+)")
        env_note["robot_contact_periods"] = last_count(robot_log, r"contact periods (\d+)")
        env_note["robot_holds"] = last_count(robot_log, r"holds begun (\d+)")
    with open(os.path.join(out, "run.json"), "w") as fh:
        json.dump(env_note, fh, indent=2)
    return codes


def run_once(args, label, avoidance):
    out = os.path.join(args.out, label)
    os.makedirs(out, exist_ok=True)
    bindir = os.path.join(args.build, "bin")
    length = session_length(args.session) / args.rate
    domain = str(args.domain + (0 if avoidance else 1))
    env_note = {"domain": int(domain), "avoidance": avoidance, "rate": args.rate, "session": args.session,
                "secure": args.secure, "robot": args.robot}
    env = None
    if args.secure:
        # Only the identity's profiles file: a default profiles file from the environment would be loaded
        # first and could hold plain participant profiles of the same names.
        env = {k: v for k, v in os.environ.items() if k != "FASTRTPS_DEFAULT_PROFILES_FILE"}

    def dds(name):
        """--domain (and, secure, --profiles of the process's identity) for process `name`."""
        if not args.secure:
            return ["--domain", domain]
        return ["--domain", domain, "--profiles",
                os.path.join(args.secure, "profiles", SECURE_IDENTITIES[name] + ".xml")]

    procs = []
    ready_timeout = args.ready_timeout or (SECURE_READY_TIMEOUT_S if args.secure else READY_TIMEOUT_S)

    def start_and_run():
        """Starts the chain (procs), waits until it is connected, replays the session through it.
        Raises StartupFailed when a link did not connect (the caller starts again)."""
        # The controller is stopped by SIGTERM when vision has finished; its --duration is only a safety
        # net should this runner die. Generous: on a loaded machine the vision replay falls behind real
        # time (seen: a 36 s session took 41 s with seven builds running), and a controller that ended on
        # its own duration first was reported as "died during the run".
        ctl_duration = 2.0 * length + 60.0 + VISION_WAIT_S + ready_timeout
        ctl = [os.path.join(bindir, "reflex_controller")] + dds("controller") + [
            "--duration", "%.1f" % ctl_duration, "--log", os.path.join(out, "controller.csv")]
        if not avoidance:
            # The comparison run shows what happens without protection: avoidance AND the e-stop off,
            # each by its own loudly named option (the controller says so in its banner and exit line).
            ctl += ["--no-avoidance", "--disable-estop"]
        if args.robot in ("mujoco", "unitree_hg"):
            # The physics robot first, so that the controller finds its state; stopped last (reverse order).
            hg = ["--interface", "unitree_hg"] if args.robot == "unitree_hg" else []
            procs.append(Proc("robot", [os.path.join(bindir, "reflex_mujoco")] + dds("robot") +
                              ["--name", "reflex_mujoco"] + hg, os.path.join(out, "robot.log"), env))
            ctl += ["--robot", "unitree_hg" if args.robot == "unitree_hg" else "dds"]
        procs.append(Proc("controller", ctl, os.path.join(out, "controller.log"), env))
        # --progress 1: its status line (joint_states=N) tells wait_chain_ready that it hears the controller.
        beh = [os.path.join(bindir, "reflex_behavior"), "--config", args.behavior, "--progress", "1"] + dds("behavior")
        procs.append(Proc("behavior", beh, os.path.join(out, "behavior.log"), env))
        recorder = os.path.join(bindir, "reflex_record")
        readers = 1  # of vision's reflex/object_targets: behavior, and the recorder when there is one
        if os.path.exists(recorder):
            # MCAP: the recording opens in Foxglove (File -> Open local file).
            rec = [recorder, "record"] + dds("recorder") + ["--output", os.path.join(out, "bus.mcap"), "--progress"]
            procs.append(Proc("recorder", rec, os.path.join(out, "recorder.log"), env))
            readers += 1
        # The live 3D view (reflex_view, reads only) during the run with avoidance, if asked for. With
        # DDS-Security: under its own identity `view`, which may only read. A view that cannot start (port in use)
        # is reported and the experiment goes on: it is a window onto the run, not part of it.
        view = os.path.join(bindir, "reflex_view")
        if args.view and avoidance and os.path.exists(view):
            procs.append(Proc("view", [view, "--port", str(args.view)] + dds("view"),
                              os.path.join(out, "view.log"), env))
            log("live 3D view of this run: http://localhost:%d (Foxglove: ws://localhost:%d)" % (args.view, args.view))
        env_note["startup_s"] = wait_chain_ready(procs, out, args.secure, ready_timeout)
        for p in procs:
            if not p.alive():
                raise RuntimeError("%s exited early (see %s)" % (p.name, p.log.name))
        env_note["vision_start_wall"] = time.time()
        # --wait-readers: vision holds its replay until behavior (and the recorder) matched its writer, so
        # the first frames are not lost to a pair still authenticating; exit 5 if they do not in time.
        vision = Proc("vision", [os.path.join(bindir, "reflex_vision"), "--session", args.session] + dds("vision") +
                      ["--rate", str(args.rate), "--quiet", "--wait-readers", str(readers),
                       "--wait-timeout", "%g" % VISION_WAIT_S], os.path.join(out, "vision.log"), env)
        procs.append(vision)
        watch_replay(vision, procs, label, length)
        if vision.p.returncode == 5:
            raise StartupFailed("vision's readers did not match: %s (see %s)" % (
                last_line(vision.log.name, "reflex_vision: error:"), vision.log.name))
        if vision.p.returncode != 0:
            raise RuntimeError("vision failed with exit code %d (see %s)" % (vision.p.returncode, vision.log.name))
        time.sleep(1.0)

    try:
        failures = []
        for attempt in range(1, STARTUP_ATTEMPTS + 1):
            try:
                start_and_run()
                break
            except StartupFailed as e:
                # Stop this chain, keep its logs as <name>.attempt<N>.log, start a fresh one: new participants
                # authenticate anew. Said in the log and in run.json (startup_failures), never silent.
                message = str(e)
                for p in reversed(procs):
                    p.stop()
                    kept = p.log.name[:-len(".log")] + ".attempt%d.log" % attempt
                    os.replace(p.log.name, kept)
                    message = message.replace(p.log.name, kept)
                failures.append(message)
                procs.clear()
                env_note["startup_failures"] = failures
                if attempt == STARTUP_ATTEMPTS:
                    raise RuntimeError("the chain did not connect in %d attempts: %s" % (attempt, " | ".join(failures)))
                log("%s; stopping the chain and starting it again (attempt %d of %d)" % (message, attempt + 1,
                                                                                          STARTUP_ATTEMPTS))
    finally:
        codes = stop_chain(args, out, procs, env_note)
    ok_codes = (0, -signal.SIGTERM, 128 + signal.SIGTERM, None)
    if codes.get("view") not in ok_codes:
        log("warning: the live view ended with exit code %s (see %s); the run itself is unaffected"
            % (codes.get("view"), os.path.join(out, "view.log")))
    bad = {k: v for k, v in codes.items() if v not in ok_codes and k != "view"}
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
    ap.add_argument("--secure", metavar="DIR",
                    help="run with DDS-Security: each process with its own identity's profiles file "
                         "DIR/profiles/<module>.xml (DIR made by bringup/security/make_security.sh when missing "
                         "or empty)")
    ap.add_argument("--robot", choices=["kinematic", "mujoco", "unitree_hg"], default="kinematic",
                    help="the plant: the controller's in-process kinematic robot, reflex_mujoco over DDS "
                         "(the controller with --robot dds), or reflex_mujoco on Unitree's hg interface (the "
                         "controller with --robot unitree_hg)")
    ap.add_argument("--ready-timeout", type=float, metavar="S", default=0.0,
                    help="seconds the chain may take to connect (behavior hears the controller, the recorder "
                         "records) before it is stopped and started again, at most %d attempts (default %g, "
                         "with --secure %g)" % (STARTUP_ATTEMPTS, READY_TIMEOUT_S, SECURE_READY_TIMEOUT_S))
    ap.add_argument("--no-report", action="store_true")
    ap.add_argument("--view", type=int, metavar="PORT", default=0,
                    help="serve the live 3D view (reflex_view) on this port during the run with avoidance")
    args = ap.parse_args()
    if not (0 <= args.domain <= 231):
        ap.error("--domain %d: must be in 0..231 (two consecutive ids are used)" % args.domain)
    if args.view and not 1 <= args.view <= 65535:
        ap.error("--view %d: a TCP port is 1..65535" % args.view)
    if args.ready_timeout < 0 or args.ready_timeout != args.ready_timeout:
        ap.error("--ready-timeout %g: must be a number of seconds >= 0 (0: the default)" % args.ready_timeout)
    if not args.rate > 0:
        ap.error("--rate %g: must be positive" % args.rate)
    for path, what in ((args.session, "session folder"), (args.behavior, "behavior configuration")):
        if not os.path.exists(path):
            ap.error("%s %s does not exist" % (what, path))
    exes = ("reflex_controller", "reflex_behavior", "reflex_vision") + (("reflex_mujoco",) if args.robot != "kinematic" else ())
    for exe in exes:
        if not os.path.exists(os.path.join(args.build, "bin", exe)):
            ap.error("%s not found in %s/bin (build first: bringup/setup.sh)" % (exe, args.build))
    mode = "plain DDS"
    if args.secure is not None:
        try:
            args.secure = check_secure_dir(args.secure)
        except ValueError as e:
            ap.error(str(e))
        mode = "DDS-Security, identities from %s" % args.secure
    runs = []
    try:
        if args.only in (None, "on"):
            log("run with collision avoidance (domain %d, %s, robot %s)" % (args.domain, mode, args.robot))
            runs.append(run_once(args, "avoidance", True))
        if args.only in (None, "off"):
            log("run WITHOUT collision avoidance, for comparison (domain %d, %s, robot %s)"
                % (args.domain + 1, mode, args.robot))
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
