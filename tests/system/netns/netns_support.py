"""Shared parts of the Python process tests that run Reflex executables in network namespaces:
tests/system/netns/netns_test.py and tests/faults/link_outage_test.py.

What is here is what both tests do the same way: shell commands that fail with their output, the
namespaces a test made (and those an earlier, killed run left behind) deleted with whatever still
runs inside, recordings exported to CSV, the processes a test started (log files, SIGTERM, exit
codes), and the list of named checks. Each test keeps its own network, scenario and assertions.

Every message a test prints starts with its tag ("netns_test: ..."), so the functions that print take
the tag. Errors raise Failure; run_test() catches it, prints "<tag>: FAIL: ..." and returns 1.
To use it from another folder, put this folder on sys.path (tests/faults/link_outage_test.py does).
"""
import csv
import os
import pathlib
import re
import signal
import subprocess
import tempfile


class Failure(Exception):
    """A test failed or could not run; the message says what, with the output that shows why."""


def sh(*argv, check=True):
    """Runs argv, returns its stdout and stderr together. With check, a non-zero exit raises Failure
    quoting the command and its output."""
    r = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if check and r.returncode != 0:
        raise Failure(f"command failed ({r.returncode}): {' '.join(argv)}\n{r.stdout}")
    return r.stdout


def add_common_arguments(ap):
    """--bin-dir, --domain and --work, as both tests' CMake registrations pass them."""
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--domain", type=int, required=True, help="DDS domain id; also the second octet of 10.x")
    ap.add_argument("--work", help="folder for logs and recordings (default: a temporary folder)")


def begin_run(tag, what, work, work_prefix, ns_prefix):
    """The start of a run: the work folder (the one --work names, made if missing, or a new temporary
    one named work_prefix*), printed as "<tag>: <what>, work folder <path>"; then the root check
    (ip netns add needs it) and remove_stale(ns_prefix). Returns the work folder as a pathlib.Path, or
    None, with "<tag>: FAIL: needs root" printed, when not running as root."""
    path = pathlib.Path(work or tempfile.mkdtemp(prefix=work_prefix))
    path.mkdir(parents=True, exist_ok=True)
    print(f"{tag}: {what}, work folder {path}", flush=True)
    if os.geteuid() != 0:
        print(f"{tag}: FAIL: needs root (ip netns add)", flush=True)
        return None
    remove_stale(ns_prefix)
    return path


def raise_failure_on_sigterm():
    """ctest's timeout sends SIGTERM: turn it into Failure("terminated") so that `finally` cleans up."""
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(Failure("terminated")))


def delete_namespaces(names):
    """Deletes each network namespace in names; whatever still runs inside (started by the test) is
    SIGKILLed first. Deleting a namespace deletes its veth ends (and their peers). Never raises for
    a namespace or process that is already gone."""
    for n in names:
        for pid in sh("ip", "netns", "pids", n, check=False).split():
            try:
                os.kill(int(pid), signal.SIGKILL)
            except (ValueError, ProcessLookupError):
                pass
        sh("ip", "netns", "del", n, check=False)


def remove_stale(prefix):
    """Namespaces named <prefix>-<pid>-... left by an earlier run that was killed (its pid no longer
    exists)."""
    for line in sh("ip", "netns", "list", check=False).splitlines():
        m = re.match(rf"({re.escape(prefix)}-(\d+)-\S+)", line)
        if m and not os.path.exists(f"/proc/{m.group(2)}"):
            sh("ip", "netns", "del", m.group(1), check=False)


def netns_exec(ns):
    """The command prefix that runs a program in namespace ns; none for ns None (this host)."""
    return ["ip", "netns", "exec", ns] if ns else []


class VethHosts:
    """Two "hosts": network namespaces <prefix>-<pid>-<host> joined by ONE veth pair, 10.<domain>.0.1 for
    the first host and 10.<domain>.0.2 for the second (nothing on the machine's real interfaces), with
    the multicast route through the veth (RTPS discovery, 239.255.0.1). build() makes them, up(h) /
    down(h) plug / pull one end, exec_prefix(h) runs a program inside, delete() removes everything it
    made (also what still runs inside). Used by tests/faults/link_outage_test.py and
    tests/mujoco/bench_mujoco_controller_latency.py."""

    def __init__(self, prefix, domain, hosts):
        pid = os.getpid()
        self.hosts = hosts
        self.ns = {h: f"{prefix}-{pid}-{h}" for h in hosts}
        # Interface names are at most 15 bytes: the prefix without its first letter, the pid, the host's initial.
        self.ifname = {h: f"{prefix[1:]}{pid % 1000000}{h[0]}" for h in hosts}
        self.addr = {h: f"10.{domain}.0.{k + 1}" for k, h in enumerate(hosts)}
        self.made = []

    def build(self):
        for h in self.hosts:
            sh("ip", "netns", "add", self.ns[h])
            self.made.append(self.ns[h])
            sh("ip", "-n", self.ns[h], "link", "set", "lo", "up")
        a, b = self.hosts
        sh("ip", "link", "add", self.ifname[a], "type", "veth", "peer", "name", self.ifname[b])
        for h in self.hosts:
            sh("ip", "link", "set", self.ifname[h], "netns", self.ns[h])
            sh("ip", "-n", self.ns[h], "addr", "add", f"{self.addr[h]}/24", "dev", self.ifname[h])
            self.up(h)

    def up(self, h):
        sh("ip", "-n", self.ns[h], "link", "set", self.ifname[h], "up")
        # RTPS multicast discovery (239.255.0.1) leaves through the veth; the route goes with the link.
        sh("ip", "-n", self.ns[h], "route", "replace", "224.0.0.0/4", "dev", self.ifname[h])

    def down(self, h):
        sh("ip", "-n", self.ns[h], "link", "set", self.ifname[h], "down")

    def exec_prefix(self, h):
        return netns_exec(self.ns[h])

    def delete(self):
        delete_namespaces(self.made)  # deletes the veth ends too
        self.made.clear()


def read_csv(path):
    """The rows of a CSV file with a header line, as dicts of strings."""
    with open(path) as fh:
        return list(csv.DictReader(fh))


def export(bin_dir, rfx, topic, out):
    """Exports one topic of recording rfx to the CSV file out with reflex_record and returns its rows;
    Failure with the tool's output if the export fails."""
    r = subprocess.run([f"{bin_dir}/reflex_record", "export", str(rfx), "--topic", topic, "--csv", str(out)],
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        raise Failure(f"export of {topic} from {rfx} failed: {r.stdout}")
    return read_csv(out)


def run_test(tag, scenario, *cleanups):
    """Runs scenario(), which raises Failure when the test fails (also on SIGTERM, see
    raise_failure_on_sigterm()); returns 0 if it returns, else prints "<tag>: FAIL: <why>" and returns 1.
    The cleanups run after it in order, whatever happened (an exception other than Failure propagates)."""
    try:
        scenario()
        return 0
    except Failure as e:
        print(f"{tag}: FAIL: {e}", flush=True)
        return 1
    finally:
        for cleanup in cleanups:
            cleanup()


class Processes:
    """The processes a test started, each writing stdout and stderr to its log file in the work folder.

    start() while the test runs; stop() to end them and collect exit codes; check_exit_codes() to fail
    on any that is not 0; close() always, from `finally` (it ends what still runs).
    """

    def __init__(self, work):
        self.work = work
        self.started = []  # (Popen, log file handle, log file name), in start order

    def start(self, argv, log, env=None):
        """Starts argv with its output in work/log (env None: this process's environment)."""
        fh = open(self.work / log, "w")
        p = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, env=env)
        self.started.append((p, fh, log))
        return p

    def _terminate(self):
        for p, _, _ in self.started:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)

    def stop(self, timeout):
        """SIGTERM to each process still running, then waits up to timeout s for each; one that hangs
        is SIGKILLed. Returns {log file name: exit code, or "killed"} in start order."""
        self._terminate()
        rcs = {}
        for p, fh, log in self.started:
            try:
                rcs[log] = p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                p.kill()
                rcs[log] = "killed"
            fh.close()
        return rcs

    def check_exit_codes(self, rcs):
        """Failure for the first process of rcs (from stop()) that did not exit 0, with its log's end."""
        for log, code in rcs.items():
            if code != 0:
                raise Failure(f"{log} ended with {code}:\n" + (self.work / log).read_text()[-3000:])

    def close(self):
        """Ends whatever still runs (SIGTERM, SIGKILL after 8 s) and closes the log files."""
        self._terminate()
        for p, fh, _ in self.started:
            try:
                p.wait(timeout=8)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
            fh.close()


class Checks:
    """The named checks of a run: check(ok, what) prints "<tag>: ok   what" or "<tag>: FAIL what" and
    keeps the result; raise_if_failed() then raises one Failure naming every check that failed."""

    def __init__(self, tag):
        self.tag = tag
        self.results = []

    def __call__(self, ok, what):
        self.results.append((ok, what))
        print(f"{self.tag}: {'ok  ' if ok else 'FAIL'} {what}", flush=True)

    def raise_if_failed(self):
        failed = [w for ok, w in self.results if not ok]
        if failed:
            raise Failure("; ".join(failed))
