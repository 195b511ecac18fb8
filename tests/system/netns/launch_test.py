#!/usr/bin/env python3
"""bringup/launch.py: the launcher starts what a configuration names, with its
environment and arguments, prefixes and collects the logs, stops everything on SIGTERM / SIGINT
(SIGKILL after stop_timeout), reports a process that dies, starts only one host's part with --host,
writes the discovery-server address into the profiles copy, and rejects bad configurations with a
message naming the bad value. Also: every shipped configuration resolves for every host, and the
generated multi-host profile files are in step with reflex_profiles.xml. Uses /bin/sh processes only.

    launch_test.py   (plain unittest; exit 0 = pass)
"""
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
import unittest

SOURCE = pathlib.Path(__file__).resolve().parents[3]
LAUNCH = SOURCE / "bringup" / "launch.py"


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is not alive
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


class LaunchTest(unittest.TestCase):
    def setUp(self):
        self.dir = pathlib.Path(tempfile.mkdtemp(prefix="launch_test_"))

    def config(self, text, name="c.yaml"):
        path = self.dir / name
        path.write_text(textwrap.dedent(text))
        return path

    def run_launch(self, *args, timeout=30):
        r = subprocess.run([sys.executable, str(LAUNCH), *map(str, args)], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, timeout=timeout)
        return r.returncode, r.stdout

    def start_launch(self, *args):
        return subprocess.Popen([sys.executable, str(LAUNCH), *map(str, args)], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)

    def wait_for(self, path, timeout=10.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if path.exists() and path.read_text().strip():
                return path.read_text()
            time.sleep(0.05)
        self.fail(f"{path} did not appear")

    def test_runs_with_environment_args_and_prefixed_logs_and_stops_all_on_sigterm(self):
        cfg = self.config(f"""
            name: basic
            domain: 89
            profiles: ${{BRINGUP}}/dds/reflex_profiles_lan.xml
            log_dir: {self.dir}/logs
            env: {{COMMON_VAR: common}}
            vars: {{greeting: hello, empty: ""}}
            processes:
              - name: first
                cmd: /bin/sh
                args: [-c, 'echo "$$REFLEX_DOMAIN_ID $$FASTRTPS_DEFAULT_PROFILES_FILE $$COMMON_VAR $$OWN $$1 $$#"; echo $$$$ > {self.dir}/first.pid; exec sleep 60', sh, "${{greeting}}", "${{empty}}"]
                env: {{OWN: own}}
              - name: second
                cmd: /bin/sh
                delay: 0.2
                args: [-c, 'echo $$$$ > {self.dir}/second.pid; trap "echo got TERM; exit 0" TERM; while true; do sleep 0.1; done']
            """)
        p = self.start_launch(cfg)
        pid1 = int(self.wait_for(self.dir / "first.pid"))
        pid2 = int(self.wait_for(self.dir / "second.pid"))
        time.sleep(0.5)
        p.send_signal(signal.SIGTERM)
        out, _ = p.communicate(timeout=20)
        self.assertEqual(p.returncode, 0, out)
        self.assertFalse(alive(pid1), "first stopped")
        self.assertFalse(alive(pid2), "second stopped")
        profiles = SOURCE / "bringup" / "dds" / "reflex_profiles_lan.xml"
        # $1 = hello, and the empty argument was left out ($# = 1)
        self.assertIn(f"[first ] 89 {profiles} common own hello 1", out)
        self.assertIn("[second] got TERM", out)
        self.assertIn("stopping (SIGTERM)", out)
        log = (self.dir / "logs" / "first.log").read_text()
        self.assertIn(f"89 {profiles} common own hello 1", log)
        self.assertTrue(log.startswith("$ /bin/sh -c"), log)

    def test_a_process_that_dies_is_reported_and_stops_the_others(self):
        cfg = self.config(f"""
            log_dir: {self.dir}/logs
            processes:
              - name: steady
                cmd: /bin/sh
                args: [-c, 'echo $$$$ > {self.dir}/steady.pid; exec sleep 60']
              - name: crasher
                cmd: /bin/sh
                delay: 0.3
                args: [-c, 'echo about to fail; exit 3']
            """)
        rc, out = self.run_launch(cfg)
        self.assertEqual(rc, 1, out)
        self.assertIn("crasher DIED (exit code 3); stopping the others", out)
        self.assertFalse(alive(int((self.dir / "steady.pid").read_text())))

    def test_on_exit_ignore_keeps_the_others_and_duration_stops_them(self):
        cfg = self.config(f"""
            log_dir: {self.dir}/logs
            processes:
              - name: steady
                cmd: /bin/sh
                args: [-c, 'exec sleep 60']
              - name: oneshot
                cmd: /bin/sh
                on_exit: ignore
                args: [-c, 'exit 0']
            """)
        t0 = time.monotonic()
        rc, out = self.run_launch(cfg, "--duration", "1.5")
        self.assertEqual(rc, 0, out)
        self.assertIn("oneshot finished (exit code 0); the others go on", out)
        self.assertIn("stopping (--duration 1.5 s)", out)
        self.assertGreater(time.monotonic() - t0, 1.4)

    def test_a_process_that_ignores_sigterm_is_killed_after_stop_timeout(self):
        cfg = self.config(f"""
            log_dir: {self.dir}/logs
            stop_timeout: 1.0
            processes:
              - name: stubborn
                cmd: /bin/sh
                args: [-c, 'trap "" TERM; echo $$$$ > {self.dir}/stubborn.pid; while true; do sleep 0.1; done']
            """)
        p = self.start_launch(cfg)
        pid = int(self.wait_for(self.dir / "stubborn.pid"))
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=20)
        self.assertIn("stubborn did not stop within 1 s: SIGKILL", out)
        self.assertEqual(p.returncode, 1, out)  # killed is not a clean stop
        self.assertFalse(alive(pid))

    def test_host_selects_a_part_and_the_discovery_server_address_is_written(self):
        cfg = self.config(f"""
            log_dir: {self.dir}/logs_${{HOST}}
            profiles: ${{BRINGUP}}/dds/reflex_profiles_discovery.xml
            hosts: {{a: {{}}, b: {{}}}}
            discovery_server: {{host: b, address: 10.1.2.3, port: 12345}}
            processes:
              - {{name: on_a, host: a, cmd: /bin/true}}
              - {{name: on_b, host: b, cmd: /bin/sh, args: [-c, 'cat $$FASTRTPS_DEFAULT_PROFILES_FILE']}}
            """)
        rc, out = self.run_launch(cfg, "--dry-run", "--host", "a")
        self.assertEqual(rc, 0, out)
        self.assertIn("[on_a @a]", out)
        self.assertNotIn("on_b", out)
        self.assertNotIn("[discovery_server]", out)
        rc, out = self.run_launch(cfg, "--dry-run", "--host", "b")
        self.assertIn("[discovery_server] fastdds discovery -i 0 -l 10.1.2.3 -p 12345", out)
        self.assertIn("[on_b @b]", out)
        self.assertNotIn("on_a", out)
        # Run host a for real: its processes get the copy with the server's address.
        cfg2 = self.config(f"""
            log_dir: {self.dir}/logs_${{HOST}}
            profiles: ${{BRINGUP}}/dds/reflex_profiles_discovery.xml
            hosts: {{a: {{}}, b: {{}}}}
            discovery_server: {{host: b, address: 10.1.2.3, port: 12345}}
            processes:
              - {{name: on_a, host: a, cmd: /bin/sh, args: [-c, 'grep -c "<address>10.1.2.3</address>" $$FASTRTPS_DEFAULT_PROFILES_FILE; grep -c "<port>12345</port>" $$FASTRTPS_DEFAULT_PROFILES_FILE']}}
            """, "c2.yaml")
        rc, out = self.run_launch(cfg2, "--host", "a")
        self.assertEqual(rc, 0, out)
        self.assertEqual(out.count("[on_a] 2\n"), 2, out)  # both participant profiles point at the server
        copy = (self.dir / "logs_a" / "profiles_reflex_profiles_discovery.xml").read_text()
        self.assertNotIn("<address>127.0.0.1</address>", copy)

    def test_several_roles_on_one_host_and_a_dry_run_that_writes_nothing(self):
        # --host takes several roles (repeated or comma-separated); the dry run
        # says what it WOULD write and writes nothing (no log folder, no profiles copy).
        cfg = self.config(f"""
            log_dir: {self.dir}/logs_${{HOST}}
            profiles: ${{BRINGUP}}/dds/reflex_profiles_discovery.xml
            hosts: {{a: {{}}, b: {{}}, c: {{}}}}
            discovery_server: {{host: b, address: 10.1.2.3, port: 12345}}
            processes:
              - {{name: on_a, host: a, cmd: /bin/true}}
              - {{name: on_b, host: b, cmd: /bin/true}}
              - {{name: on_c, host: c, cmd: /bin/true}}
            """)
        for hosts in (["--host", "a,b"], ["--host", "a", "--host", "b"]):
            rc, out = self.run_launch(cfg, "--dry-run", *hosts)
            self.assertEqual(rc, 0, out)
            self.assertIn("[on_a @a]", out)
            self.assertIn("[on_b @b]", out)
            self.assertIn("[discovery_server]", out)
            self.assertNotIn("on_c", out)
            self.assertIn(f"profiles would be written to {self.dir}/logs_a+b/profiles_reflex_profiles_discovery.xml", out)
            self.assertNotIn("profiles written", out)
        self.assertEqual(sorted(p.name for p in self.dir.iterdir()), ["c.yaml"], "a dry run writes nothing")
        rc, out = self.run_launch(cfg, "--dry-run", "--host", "a,moon")
        self.assertEqual(rc, 2, out)
        self.assertIn("--host 'moon'", out)
        rc, out = self.run_launch(cfg, "--dry-run", "--host", "a,")
        self.assertEqual(rc, 2, out)
        self.assertIn("empty host name", out)

    def test_the_final_line_says_stopped_for_what_the_launcher_stopped(self):
        # A process the launcher stopped (SIGTERM) showed as "-15".
        cfg = self.config(f"""
            log_dir: {self.dir}/logs
            processes:
              - {{name: sleeper, cmd: /bin/sh, args: [-c, 'exec sleep 60']}}
              - {{name: trapper, cmd: /bin/sh, args: [-c, 'trap "exit 0" TERM; while true; do sleep 0.1; done']}}
              - {{name: oneshot, cmd: /bin/sh, on_exit: ignore, args: [-c, 'exit 0']}}
            """)
        rc, out = self.run_launch(cfg, "--duration", "1")
        self.assertEqual(rc, 0, out)
        self.assertIn("all stopped: sleeper=stopped, trapper=stopped, oneshot=0", out)
        self.assertNotIn("-15", out)

    def test_logs_default_outside_the_checkout(self):
        # Without log_dir the logs go to $REFLEX_LOG_DIR/launch/<name> (else
        # ~/.reflex/log/...), never into the source tree; every shipped configuration follows it.
        cfg = self.config("""
            name: nolog
            processes:
              - {name: hello, cmd: /bin/sh, args: [-c, 'echo hi']}
            """)
        env = dict(os.environ, REFLEX_LOG_DIR=str(self.dir / "root"))
        r = subprocess.run([sys.executable, str(LAUNCH), str(cfg)], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, timeout=30, env=env)
        self.assertEqual(r.returncode, 0, r.stdout)
        self.assertIn("hi", (self.dir / "root" / "launch" / "nolog" / "hello.log").read_text())
        for shipped in sorted((SOURCE / "bringup" / "launch").glob("*.yaml")):
            r = subprocess.run([sys.executable, str(LAUNCH), str(shipped), "--dry-run"], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, timeout=30, env=env)
            self.assertEqual(r.returncode, 0, r.stdout)
            self.assertIn(f"logs would go to {self.dir / 'root' / 'launch'}", r.stdout, shipped)
            self.assertNotIn(str(SOURCE / "out"), r.stdout, shipped)

    def test_the_session_loop_is_a_launch_variable(self):
        # --loop for the session replay without editing the configuration.
        for shipped in sorted((SOURCE / "bringup" / "launch").glob("*.yaml")):
            rc, out = self.run_launch(shipped, "--dry-run")
            vision = [line for line in out.splitlines() if line.startswith("[vision")]
            self.assertEqual(len(vision), 1, out)
            self.assertNotIn("--loop", vision[0])
            rc, out = self.run_launch(shipped, "--dry-run", "--set", "session_loop=--loop")
            self.assertEqual(rc, 0, out)
            vision = [line for line in out.splitlines() if line.startswith("[vision")]
            self.assertIn(" --loop ", vision[0], shipped)

    def test_the_robot_side_starts_reflex_mujoco_and_the_controller_over_dds(self):
        # --robot mujoco starts the processes marked robot: mujoco (reflex_mujoco)
        # before the controller, which then runs with --robot dds; kinematic (the default) neither.
        for shipped in sorted((SOURCE / "bringup" / "launch").glob("*.yaml")):
            for side, port in (("kinematic", "kinematic"), ("mujoco", "dds")):
                extra = ["--host", "robot"] if "hosts:" in shipped.read_text() else []
                rc, out = self.run_launch(shipped, "--dry-run", "--robot", side, *extra)
                self.assertEqual(rc, 0, f"{shipped} --robot {side}: {out}")
                lines = [line for line in out.splitlines() if line.startswith("[")]
                names = [line.split("]")[0].strip("[").split(" ")[0] for line in lines]
                controller = [line for line in lines if line.startswith("[controller")]
                self.assertEqual(len(controller), 1, out)
                self.assertIn(f" --robot {port}", controller[0], shipped)
                if side == "mujoco":
                    self.assertIn("robot", names, out)
                    self.assertIn("reflex_mujoco", lines[names.index("robot")])
                    self.assertLess(names.index("robot"), names.index("controller"), out)
                else:
                    self.assertNotIn("robot", names, out)
        cfg = self.config(f"log_dir: {self.dir}/r\nprocesses: [{{name: x, cmd: /bin/true, robot: gazebo}}]", "r.yaml")
        rc, out = self.run_launch(cfg, "--dry-run")
        self.assertEqual(rc, 2, out)
        self.assertIn("robot 'gazebo'", out)
        rc, out = self.run_launch(SOURCE / "bringup" / "launch" / "one_host.yaml", "--dry-run", "--robot", "gazebo")
        self.assertEqual(rc, 2, out)
        self.assertIn("--robot 'gazebo'", out)

    def test_bad_configurations_name_the_bad_value(self):
        cases = [
            ("processes: [{name: x, cmd: /bin/true, colour: red}]", "colour"),
            ("processes: [{name: x, cmd: /bin/true, args: ['${nope}']}]", "${nope}"),
            ("domain: 400\nprocesses: [{name: x, cmd: /bin/true}]", "400"),
            ("processes: [{name: x, cmd: /bin/true}, {name: x, cmd: /bin/true}]", "'x' used twice"),
            ("hosts: {a: {}}\nprocesses: [{name: x, host: z, cmd: /bin/true}]", "host 'z'"),
            ("processes: [{name: x, cmd: /bin/true, on_exit: explode}]", "explode"),
            ("processes: [{name: x, cmd: no_such_program_here}]", "no_such_program_here"),
            ("processes: []", "non-empty"),
            ("processes: [{name: x: y}", "not valid YAML"),
        ]
        for i, (text, needle) in enumerate(cases):
            cfg = self.config(f"log_dir: {self.dir}/bad\n" + text, f"bad{i}.yaml")
            rc, out = self.run_launch(cfg, "--bin-dir", self.dir)
            self.assertEqual(rc, 2, f"{text}\n{out}")
            self.assertIn(needle, out, text)
        rc, out = self.run_launch(self.dir / "missing.yaml")
        self.assertEqual(rc, 2)
        self.assertIn("missing.yaml", out)
        rc, out = self.run_launch(SOURCE / "bringup" / "launch" / "multi_host.yaml", "--host", "moon", "--dry-run")
        self.assertEqual(rc, 2)
        self.assertIn("'moon'", out)
        rc, out = self.run_launch(SOURCE / "bringup" / "launch" / "one_host.yaml", "--set", "colour=red", "--dry-run")
        self.assertEqual(rc, 2)
        self.assertIn("colour", out)

    def test_every_shipped_configuration_resolves_for_every_host(self):
        configs = sorted((SOURCE / "bringup" / "launch").glob("*.yaml"))
        self.assertGreaterEqual(len(configs), 3)
        started = {}
        for cfg in configs:
            rc, out = self.run_launch(cfg, "--dry-run")
            self.assertEqual(rc, 0, f"{cfg}: {out}")
            names = [line.split("]")[0].strip("[").split(" ")[0] for line in out.splitlines() if line.startswith("[")]
            started[cfg.name] = set(names)
            for host in ("vision", "behavior", "robot"):
                if "hosts:" in cfg.read_text():
                    rc, out = self.run_launch(cfg, "--dry-run", "--host", host)
                    self.assertEqual(rc, 0, f"{cfg} --host {host}: {out}")
        for name in ("one_host.yaml", "multi_host.yaml", "multi_host_discovery.yaml"):
            self.assertTrue({"vision", "behavior", "controller", "recorder"} <= started[name], (name, started[name]))
        self.assertIn("discovery_server", started["multi_host_discovery.yaml"])

    def test_generated_profile_files_are_in_step_with_reflex_profiles_xml(self):
        r = subprocess.run([sys.executable, str(SOURCE / "bringup" / "dds" / "make_profiles.py"), "--check"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.assertEqual(r.returncode, 0, r.stdout)

    def test_every_profiles_file_is_well_formed_xml(self):
        # Fast DDS's parser tolerates "--" inside a comment; a strict XML parser (Python's, other
        # tools, the link-outage test that reads the leases) does not. Seen: "(--robot-timeout)".
        import xml.etree.ElementTree as ET
        files = sorted((SOURCE / "bringup" / "dds").glob("*.xml"))
        self.assertGreaterEqual(len(files), 3)
        for f in files:
            try:
                ET.parse(f)
            except ET.ParseError as e:
                self.fail(f"{f}: {e}")


if __name__ == "__main__":
    unittest.main(verbosity=2)
