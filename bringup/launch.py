#!/usr/bin/env python3
"""reflex launch: start the Reflex processes a YAML launch configuration names.

    bringup/launch.py bringup/launch/one_host.yaml                      # everything on this host
    bringup/launch.py bringup/launch/multi_host.yaml --host robot       # this host's part only
    bringup/launch.py bringup/launch/multi_host.yaml --host vision,behavior   # two roles on one machine
    bringup/launch.py bringup/launch/multi_host.yaml --dry-run          # show what would start where
    bringup/launch.py CONFIG --set session=/data/my_session --duration 70
    bringup/launch.py bringup/launch/one_host.yaml --robot mujoco       # the physics robot (reflex_mujoco)
    bringup/launch.py bringup/launch/one_host.yaml --robot unitree_hg   # the same on Unitree's hg interface

Every process gets the configuration's DDS domain (REFLEX_DOMAIN_ID) and profiles file
(FASTRTPS_DEFAULT_PROFILES_FILE), both read by reflex::bus in every Reflex process; its output is
prefixed with its name on this terminal and written whole to <log_dir>/<name>.log (by default under
$REFLEX_LOG_DIR, else ~/.reflex/log: outside the checkout, like ROS's ~/.ros/log). Ctrl-C / SIGTERM
stops all processes (SIGTERM to each process group in reverse start order, one after the other,
SIGKILL after stop_timeout). A process that exits is reported; by default (on_exit: shutdown) its exit stops the
others. Exit code: 0 if every process ended normally (finished with 0 or stopped by the launcher),
1 if one failed, 2 for a bad configuration or command line.

The configuration format is documented in bringup/README.md (section "Launch").
"""
import argparse
import os
import pathlib
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time

try:
    import yaml
except ImportError:  # python3-yaml (Debian) is installed by bringup/setup.sh
    sys.stderr.write("launch.py: needs PyYAML (Debian package python3-yaml)\n")
    sys.exit(2)

HERE = pathlib.Path(__file__).resolve().parent          # bringup/
SOURCE = HERE.parent                                    # the checkout

PROCESS_KEYS = {"name", "cmd", "args", "host", "env", "prefix", "on_exit", "delay", "stop_signal", "enabled", "robot"}
TOP_KEYS = {"name", "description", "domain", "profiles", "log_dir", "bin_dir", "env", "vars", "hosts",
            "discovery_server", "processes", "stop_timeout", "robot"}
# The robot side: "kinematic" = the controller's in-process plant; "mujoco" = reflex_mujoco
# on the bus, the controller with --robot dds; "unitree_hg" = reflex_mujoco speaking Unitree's hg
# interface, the controller with --robot unitree_hg (the joint map beside the URDF). A process with
# `robot: X` starts only on side X; ${ROBOT} is the side, ${ROBOT_PORT} the controller's --robot value
# (kinematic | dds | unitree_hg).
ROBOT_SIDES = {"kinematic": "kinematic", "mujoco": "dds", "unitree_hg": "unitree_hg"}
SIGNALS = {"SIGINT": signal.SIGINT, "SIGTERM": signal.SIGTERM, "SIGKILL": signal.SIGKILL, "SIGUSR1": signal.SIGUSR1}


class ConfigError(Exception):
    """A bad launch configuration or command line (message names the file, key and value)."""


def substitute(value, variables, where):
    """Replaces ${NAME} in a string (recursively in lists); $$ is a literal $."""
    if isinstance(value, list):
        return [substitute(v, variables, where) for v in value]
    if not isinstance(value, str):
        return str(value)

    def repl(m):
        if m.group(0) == "$$":
            return "$"
        name = m.group(1)
        if name not in variables:
            raise ConfigError(f"{where}: unknown variable '${{{name}}}' (known: {', '.join(sorted(variables))})")
        return str(variables[name])

    return re.sub(r"\$\$|\$\{([A-Za-z_][A-Za-z0-9_]*)\}", repl, value)


class Process:
    def __init__(self, spec, index, config):
        self.spec = spec
        self.name = spec["name"]
        self.host = spec.get("host")
        self.index = index
        self.config = config
        self.popen = None
        self.log_file = None
        self.threads = []
        self.returncode = None
        self.stopped_by_launcher = False
        self.argv = []
        self.exe = ""
        self.env = {}


class Launch:
    def __init__(self, path, args):
        self.path = pathlib.Path(path)
        self.args = args
        try:
            text = self.path.read_text()
        except OSError as e:
            raise ConfigError(f"cannot read launch configuration '{path}': {e.strerror}")
        try:
            self.doc = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise ConfigError(f"'{path}' is not valid YAML: {e}")
        if not isinstance(self.doc, dict):
            raise ConfigError(f"'{path}': the top level must be a mapping with a 'processes' list")
        unknown = set(self.doc) - TOP_KEYS
        if unknown:
            raise ConfigError(f"'{path}': unknown key(s) {sorted(unknown)} (known: {sorted(TOP_KEYS)})")
        self.lock = threading.Lock()
        self.processes = []
        self._resolve()

    # ---- configuration ---------------------------------------------------------------------
    def _resolve(self):
        doc, args = self.doc, self.args
        where = str(self.path)
        domain = args.domain if args.domain is not None else doc.get("domain", os.environ.get("REFLEX_DOMAIN_ID", 0))
        try:
            domain = int(domain)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: domain '{domain}' is not an integer")
        if not 0 <= domain <= 232:
            raise ConfigError(f"{where}: domain {domain} is outside 0..232")
        self.domain = domain
        build = os.environ.get("REFLEX_BUILD_DIR", str(SOURCE / "build"))
        bin_dir = args.bin_dir or doc.get("bin_dir") or os.environ.get("REFLEX_BIN_DIR") or os.path.join(build, "bin")
        # HOST: the host(s) this launcher starts (--host; several joined with "+"), "all" without
        # --host; in a process's own fields it is that process's host.
        # LOG_ROOT: where logs go unless a configuration says otherwise: $REFLEX_LOG_DIR, else
        # ~/.reflex/log (never inside the checkout, which may be read-only or shared).
        self.hosts_selected = parse_hosts(args.host)
        robot = args.robot or str(doc.get("robot", "kinematic"))
        if robot not in ROBOT_SIDES:
            origin = "--robot" if args.robot else f"{where}: robot"
            raise ConfigError(f"{origin} '{robot}' must be one of {sorted(ROBOT_SIDES)}")
        self.robot = robot
        variables = {"BRINGUP": str(HERE), "SOURCE": str(SOURCE), "CONFIG_DIR": str(self.path.resolve().parent),
                     "DOMAIN": str(domain), "BIN": bin_dir, "LOG_ROOT": default_log_root(),
                     "HOST": "+".join(self.hosts_selected) if self.hosts_selected else "all",
                     "ROBOT": robot, "ROBOT_PORT": ROBOT_SIDES[robot]}
        vars_ = doc.get("vars") or {}
        if not isinstance(vars_, dict):
            raise ConfigError(f"{where}: 'vars' must be a mapping")
        for k, v in vars_.items():
            variables[k] = substitute(v, variables, f"{where}: vars.{k}")
        for item in args.set or []:
            if "=" not in item:
                raise ConfigError(f"--set '{item}' must be NAME=VALUE")
            k, v = item.split("=", 1)
            if k not in vars_:
                raise ConfigError(f"--set '{k}': the configuration has no such variable (vars: {sorted(vars_)})")
            variables[k] = v
        self.bin_dir = os.path.abspath(substitute(bin_dir, variables, f"{where}: bin_dir"))
        variables["BIN"] = self.bin_dir
        log_dir = args.log_dir or doc.get("log_dir", "${LOG_ROOT}/launch/${NAME}")
        variables["NAME"] = re.sub(r"[^A-Za-z0-9_.-]", "_", str(doc.get("name", self.path.stem)))
        self.log_dir = pathlib.Path(substitute(log_dir, variables, f"{where}: log_dir"))
        variables["LOG_DIR"] = str(self.log_dir)
        self.variables = variables

        hosts = doc.get("hosts") or {}
        if not isinstance(hosts, dict):
            raise ConfigError(f"{where}: 'hosts' must be a mapping of host name -> {{address: ...}}")
        self.hosts = hosts
        for h in self.hosts_selected or []:
            if h not in hosts:
                raise ConfigError(f"--host '{h}' is not a host of {where} (hosts: {sorted(hosts) or 'none'})")

        profiles = doc.get("profiles")
        self.profiles = substitute(profiles, variables, f"{where}: profiles") if profiles else None
        if args.profiles:
            self.profiles = args.profiles
        self.discovery = None
        ds = doc.get("discovery_server")
        if ds is not None:
            if not isinstance(ds, dict) or "address" not in ds:
                raise ConfigError(f"{where}: discovery_server needs at least 'address' (and 'port', 'host')")
            address = substitute(ds["address"], variables, f"{where}: discovery_server.address")
            if args.discovery_address:
                address = args.discovery_address
            port = int(ds.get("port", 11811))
            server_host = ds.get("host")
            if server_host is not None and server_host not in hosts:
                raise ConfigError(f"{where}: discovery_server.host '{server_host}' is not in hosts {sorted(hosts)}")
            self.discovery = {"address": address, "port": port, "host": server_host}
        self.stop_timeout = float(doc.get("stop_timeout", 5.0))

        self._resolve_processes(where, variables, hosts, robot)

    def _resolve_processes(self, where, variables, hosts, robot):
        """The configuration's processes, each checked (name, host, on_exit, stop_signal, robot side) and,
        if enabled for this robot side, resolved into a Process (command, arguments, environment)."""
        doc = self.doc
        base_env = {k: substitute(v, variables, f"{where}: env.{k}") for k, v in (doc.get("env") or {}).items()}
        specs = doc.get("processes")
        if not isinstance(specs, list) or not specs:
            raise ConfigError(f"{where}: 'processes' must be a non-empty list")
        names = set()
        for i, spec in enumerate(specs):
            w = f"{where}: processes[{i}]"
            if not isinstance(spec, dict) or "name" not in spec or "cmd" not in spec:
                raise ConfigError(f"{w}: every process needs 'name' and 'cmd'")
            unknown = set(spec) - PROCESS_KEYS
            if unknown:
                raise ConfigError(f"{w} ('{spec['name']}'): unknown key(s) {sorted(unknown)} (known: {sorted(PROCESS_KEYS)})")
            if spec["name"] in names:
                raise ConfigError(f"{w}: process name '{spec['name']}' used twice")
            names.add(spec["name"])
            if hosts and spec.get("host") not in hosts:
                raise ConfigError(f"{w} ('{spec['name']}'): host '{spec.get('host')}' is not in hosts {sorted(hosts)}")
            if not hosts and spec.get("host") is not None:
                raise ConfigError(f"{w} ('{spec['name']}'): has a host but the configuration has no 'hosts'")
            on_exit = spec.get("on_exit", "shutdown")
            if on_exit not in ("shutdown", "ignore"):
                raise ConfigError(f"{w} ('{spec['name']}'): on_exit '{on_exit}' must be 'shutdown' or 'ignore'")
            sig = spec.get("stop_signal", "SIGTERM")
            if sig not in SIGNALS:
                raise ConfigError(f"{w} ('{spec['name']}'): stop_signal '{sig}' must be one of {sorted(SIGNALS)}")
            side = spec.get("robot")
            if side is not None and side not in ROBOT_SIDES:
                raise ConfigError(f"{w} ('{spec['name']}'): robot '{side}' must be one of {sorted(ROBOT_SIDES)}")
            if not spec.get("enabled", True) or (side is not None and side != robot):
                continue
            p = Process(spec, i, self)
            pv = dict(variables, HOST=str(spec.get("host") or ""), PROCESS=spec["name"])
            cmd = substitute(spec["cmd"], pv, f"{w}.cmd")
            args_ = spec.get("args") or []
            if isinstance(args_, str):
                args_ = shlex.split(args_)
            prefix = spec.get("prefix") or []
            if isinstance(prefix, str):
                prefix = shlex.split(prefix)
            p.exe = self._which(cmd)
            # An argument that substitutes to "" is left out (e.g. an optional flag in a variable).
            argv = substitute(list(args_), pv, f"{w}.args")
            p.argv = substitute(prefix, pv, f"{w}.prefix") + [p.exe] + [a for a in argv if a != ""]
            p.env = dict(base_env)
            p.env.update({k: substitute(v, pv, f"{w}.env.{k}") for k, v in (spec.get("env") or {}).items()})
            p.delay = float(spec.get("delay", 0.0))
            p.on_exit = on_exit
            p.stop_signal = SIGNALS[sig]
            self.processes.append(p)

    def _which(self, cmd):
        if "/" in cmd:
            return cmd
        candidate = os.path.join(self.bin_dir, cmd)
        if os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return candidate
        found = shutil.which(cmd)
        return found if found else candidate  # reported as missing at start

    def selected(self):
        if self.hosts_selected is None:
            return list(self.processes)
        return [p for p in self.processes if p.host in self.hosts_selected]

    def runs_discovery_server(self):
        d = self.discovery
        return d is not None and (self.hosts_selected is None or d["host"] is None or d["host"] in self.hosts_selected)

    def common_env(self):
        env = {"REFLEX_DOMAIN_ID": str(self.domain)}
        if self.profiles:
            env["FASTRTPS_DEFAULT_PROFILES_FILE"] = self.effective_profiles()
        return env

    def effective_profiles(self):
        """The profiles file the processes load: with a discovery server, a copy of the configured file
        with the server's address and port in it (written to the log folder)."""
        if not self.discovery:
            return self.profiles
        return str(self.log_dir / ("profiles_" + pathlib.Path(self.profiles).name))

    def write_profiles(self):
        if not self.discovery:
            return
        src = pathlib.Path(self.profiles)
        try:
            text = src.read_text()
        except OSError as e:
            raise ConfigError(f"cannot read profiles file '{src}': {e.strerror}")
        block = re.compile(r"(<RemoteServer\b.*?<address>)[^<]*(</address>\s*<port>)[^<]*(</port>)", re.S)
        if not block.search(text):
            raise ConfigError(f"profiles file '{src}' has no <RemoteServer> locator (a discovery_server launch "
                              "needs a discovery-client profile such as dds/reflex_profiles_discovery.xml)")
        text = block.sub(lambda m: f"{m.group(1)}{self.discovery['address']}{m.group(2)}{self.discovery['port']}{m.group(3)}",
                         text)
        out = pathlib.Path(self.effective_profiles())
        out.write_text(text)

    def discovery_argv(self):
        d = self.discovery
        return ["fastdds", "discovery", "-i", "0", "-l", d["address"], "-p", str(d["port"])]

    # ---- dry run -----------------------------------------------------------------------------
    def dry_run(self):
        out = sys.stdout
        target = f"host(s) {', '.join(repr(h) for h in self.hosts_selected)}" if self.hosts_selected else "all hosts"
        out.write(f"# dry run: nothing is started or written\n")
        out.write(f"# {self.doc.get('name', self.path.stem)}: {target}, domain {self.domain}, logs would go to {self.log_dir}\n")
        env = self.common_env()
        for k, v in env.items():
            out.write(f"export {k}={shlex.quote(v)}\n")
        if self.discovery:
            out.write(f"# profiles would be written to {self.effective_profiles()} with discovery server "
                      f"{self.discovery['address']}:{self.discovery['port']} (from {self.profiles})\n")
        if self.runs_discovery_server():
            out.write(f"[discovery_server] {' '.join(shlex.quote(a) for a in self.discovery_argv())}\n")
        for p in self.selected():
            envs = " ".join(f"{k}={shlex.quote(v)}" for k, v in p.env.items())
            missing = "" if os.path.exists(p.exe) else "   # (not built yet)"
            host = f" @{p.host}" if p.host else ""
            delay = f" (after {p.delay:g} s)" if p.delay else ""
            out.write(f"[{p.name}{host}]{delay} {envs + ' ' if envs else ''}"
                      f"{' '.join(shlex.quote(a) for a in p.argv)}{missing}\n")
        return 0

    # ---- running -----------------------------------------------------------------------------
    def say(self, text):
        with self.lock:
            sys.stdout.write(f"[launch] {text}\n")
            sys.stdout.flush()

    def _pump(self, p, stream):
        width = max(len(q.name) for q in self.all_started) if self.all_started else len(p.name)
        for raw in iter(stream.readline, b""):
            line = raw.decode("utf-8", "replace").rstrip("\r\n")
            with self.lock:
                p.log_file.write(raw)
                p.log_file.flush()
                if not self.args.quiet:
                    # Progress lines redraw with \r: keep only the last state.
                    sys.stdout.write(f"[{p.name:<{width}}] {line.split(chr(13))[-1]}\n")
                    sys.stdout.flush()
        stream.close()

    def _start(self, p):
        exe = p.exe
        if not os.path.exists(exe):
            raise ConfigError(f"process '{p.name}': executable '{exe}' not found (build it, or give --bin-dir)")
        env = dict(os.environ)
        env.update(self.common_env())
        env.update(p.env)
        p.log_file = open(self.log_dir / f"{p.name}.log", "wb")
        p.log_file.write(("$ " + " ".join(shlex.quote(a) for a in p.argv) + "\n").encode())
        # Own session = own process group: the launcher, not the terminal, delivers Ctrl-C, and a
        # process's children (e.g. fastdds -> fast-discovery-server) are stopped with it.
        p.popen = subprocess.Popen(p.argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, start_new_session=True)
        self.say(f"started {p.name} (pid {p.popen.pid}){' on host ' + p.host if p.host else ''}")
        t = threading.Thread(target=self._pump, args=(p, p.popen.stdout), daemon=True)
        t.start()
        p.threads.append(t)

    def _signal(self, p, sig):
        if p.popen and p.popen.poll() is None:
            try:
                os.killpg(p.popen.pid, sig)
            except ProcessLookupError:
                pass

    def stop_all(self, started):
        """Stops in reverse start order, one after the other, so that e.g. the recorder (started first)
        still records what the others publish while they stop (a behavior's final "no target")."""
        for p in reversed(started):
            if not p.popen:
                continue
            if p.popen.poll() is None:
                p.stopped_by_launcher = True
                self._signal(p, p.stop_signal)
                try:
                    p.popen.wait(timeout=self.stop_timeout)
                except subprocess.TimeoutExpired:
                    self.say(f"{p.name} did not stop within {self.stop_timeout:g} s: SIGKILL")
                    self._signal(p, signal.SIGKILL)
                    p.popen.wait()
            # The group may still hold children (e.g. the discovery server under the fastdds wrapper).
            try:
                os.killpg(p.popen.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass

    def run(self):
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.write_profiles()
        stop = threading.Event()
        reason = {"why": None}

        def on_signal(signum, _frame):
            reason["why"] = signal.Signals(signum).name
            stop.set()

        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        started = []
        chosen = list(self.selected())
        if self.runs_discovery_server():
            ds = Process({"name": "discovery_server", "cmd": "fastdds"}, -1, self)
            ds.argv = self.discovery_argv()
            ds.argv[0] = ds.exe = shutil.which("fastdds") or "/usr/bin/fastdds"
            ds.env, ds.delay, ds.on_exit, ds.stop_signal = {}, 0.0, "shutdown", signal.SIGTERM
            chosen.insert(0, ds)
        if not chosen:
            self.say(f"nothing to start for host(s) {', '.join(self.hosts_selected or [])}")
            return 0
        self.all_started = chosen
        self.say(f"{self.doc.get('name', self.path.stem)}: domain {self.domain}, profiles "
                 f"{self.effective_profiles() or '(default)'}, logs in {self.log_dir}")
        failed = False
        t_end = time.monotonic() + self.args.duration if self.args.duration else None
        try:
            for p in chosen:
                if stop.wait(p.delay if p.delay > 0 else 0):
                    break
                self._start(p)
                started.append(p)
                if p.name == "discovery_server":
                    stop.wait(0.5)  # let the server bind before clients announce themselves
            while not stop.is_set():
                if t_end is not None and time.monotonic() >= t_end:
                    reason["why"] = f"--duration {self.args.duration:g} s"
                    break
                for p in started:
                    if p.returncode is None and p.popen.poll() is not None:
                        p.returncode = p.popen.returncode
                        rc = p.returncode
                        how = f"exit code {rc}" if rc >= 0 else f"signal {signal.Signals(-rc).name}"
                        bad = rc != 0
                        failed |= bad
                        self.say(f"{p.name} {'DIED' if bad else 'finished'} ({how})"
                                 + ("; stopping the others" if p.on_exit == "shutdown" else "; the others go on"))
                        if p.on_exit == "shutdown":
                            reason["why"] = f"{p.name} exited"
                            stop.set()
                if started and all(p.returncode is not None for p in started):
                    break
                stop.wait(0.1)
        except ConfigError:
            self.stop_all(started)
            raise
        if reason["why"]:
            self.say(f"stopping ({reason['why']})")
        self.stop_all(started)
        for p in started:
            for t in p.threads:
                t.join(timeout=2.0)
            if p.log_file:
                p.log_file.close()
            rc = p.popen.returncode
            if p.returncode is None:
                p.returncode = rc
                # Stopped by us: exit 0 or death by our own stop signal is a normal stop.
                if rc not in (0, -p.stop_signal, 128 + p.stop_signal, 130, 143):
                    failed = True
                    self.say(f"{p.name} ended badly when stopped (exit {rc})")
        summary = ", ".join(f"{p.name}={outcome(p)}" for p in started)
        self.say(f"all stopped: {summary}")
        return 1 if failed else 0


def parse_hosts(values):
    """--host values (repeatable, comma-separated) -> list of host names in the order given, or None."""
    if not values:
        return None
    hosts = []
    for v in values:
        for h in v.split(","):
            h = h.strip()
            if not h:
                raise ConfigError(f"--host '{v}': empty host name")
            if h not in hosts:
                hosts.append(h)
    return hosts


def default_log_root():
    """$REFLEX_LOG_DIR, else ~/.reflex/log."""
    root = os.environ.get("REFLEX_LOG_DIR")
    if root:
        return root
    return str(pathlib.Path.home() / ".reflex" / "log")


def outcome(p):
    """How a process ended, for the final line: its exit code; "stopped" when the launcher stopped it
    and it ended by that stop (exit 0 or its stop signal); a signal by name otherwise."""
    rc = p.returncode
    if rc is None:
        return "?"
    if p.stopped_by_launcher and rc in (0, -p.stop_signal, 128 + p.stop_signal, 130, 143):
        return "stopped"
    if rc < 0:
        return signal.Signals(-rc).name
    return str(rc)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="launch.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", help="launch configuration YAML (e.g. bringup/launch/one_host.yaml)")
    ap.add_argument("--host", action="append", metavar="HOST[,HOST...]",
                    help="start only the processes assigned to these hosts (multi-host configurations); "
                         "repeat or separate with commas to run several roles on one machine")
    ap.add_argument("--dry-run", action="store_true", help="print the environment and commands, start nothing")
    ap.add_argument("--duration", type=float, default=0.0, help="stop everything after this many seconds")
    ap.add_argument("--domain", type=int, help="override the configuration's DDS domain id")
    ap.add_argument("--profiles", help="override the configuration's DDS profiles file")
    ap.add_argument("--discovery-address", help="override the discovery server address")
    ap.add_argument("--bin-dir", help="folder of the Reflex executables (default: $REFLEX_BUILD_DIR/bin or build/bin)")
    ap.add_argument("--log-dir", help="folder for the process logs (default: the configuration's log_dir)")
    ap.add_argument("--set", action="append", metavar="NAME=VALUE", help="set a variable of the configuration's vars")
    ap.add_argument("--quiet", action="store_true", help="do not echo process output (logs are still written)")
    ap.add_argument("--robot", help="the robot side: kinematic (the controller's in-process plant), mujoco "
                                    "(starts the processes marked 'robot: mujoco', i.e. reflex_mujoco, and the "
                                    "controller with --robot dds) or unitree_hg (the processes marked 'robot: "
                                    "unitree_hg', reflex_mujoco on Unitree's hg interface, and the controller with "
                                    "--robot unitree_hg); default: the configuration's 'robot' or kinematic")
    args = ap.parse_args(argv)
    if args.duration < 0:
        ap.error(f"--duration {args.duration} must not be negative")
    try:
        launch = Launch(args.config, args)
        if args.dry_run:
            return launch.dry_run()
        return launch.run()
    except ConfigError as e:
        sys.stderr.write(f"launch.py: error: {e}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
