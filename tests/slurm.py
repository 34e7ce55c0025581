"""A real one-node SLURM on localhost for the tests of jobs/ (Debian's slurmctld/slurmd).

    cluster = LocalSlurm(tmpdir)     # everything lives under tmpdir (config, state, spool, logs)
    cluster.start()                  # raises SlurmUnavailable(reason) if SLURM cannot run here
    jid = cluster.sbatch(script, args, options=["-n", "2"], env={...})
    cluster.wait_gone(jid)
    cluster.stop()                   # cancels the jobs, stops the daemons by PID

The daemons run in the foreground (-D) as children of this process, on two
free ports, with auth/none and cred/none (no munge), a fresh StateSaveLocation
and a node that claims 4 CPUs (config_overrides) whatever the machine has.
The clients find the cluster through SLURM_CONF in `cluster.env`; nothing is
written outside tmpdir and no system daemon is touched.
"""
from __future__ import annotations

import getpass
import os
import shutil
import signal
import socket
import subprocess
import time

SBIN = ("/usr/sbin", "/usr/local/sbin", "/sbin")
CLIENTS = ("sbatch", "squeue", "scontrol", "sinfo", "scancel")
DAEMONS = ("slurmctld", "slurmd")
PACKAGES = "slurmctld slurmd slurm-client"


class SlurmUnavailable(RuntimeError):
    """SLURM cannot run here; the message says why (for pytest.skip)."""


def which(name: str) -> str | None:
    return shutil.which(name) or shutil.which(name, path=os.pathsep.join(SBIN))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _alive(pid: int) -> bool:
    """True while pid exists and is not a zombie (PID 1 here does not reap orphans)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def clean_env(base: dict | None = None) -> dict:
    """A copy of the environment without a surrounding job's SLURM_*/SBATCH_* variables."""
    env = dict(os.environ if base is None else base)
    for k in list(env):
        if k.startswith(("SLURM_", "SBATCH_", "SALLOC_", "SRUN_")):
            del env[k]
    return env


class LocalSlurm:
    def __init__(self, base: str, cpus: int = 4, cred_expire: int = 10):
        self.base = os.path.abspath(base)
        self.cpus = cpus
        self.cred_expire = cred_expire
        self.conf = os.path.join(self.base, "slurm.conf")
        self.marker = f"HPCWEDGE_TEST_SLURM={self.base}"
        self.env = clean_env()
        self.env["SLURM_CONF"] = self.conf
        self.env["HPCWEDGE_TEST_SLURM"] = self.base   # marks every process started for this cluster
        self.procs: dict[str, subprocess.Popen] = {}
        self.paths = {n: which(n) for n in CLIENTS + DAEMONS}

    # -- set-up -----------------------------------------------------------------
    def write_config(self) -> None:
        for d in ("state", "spool", "log"):
            os.makedirs(os.path.join(self.base, d), exist_ok=True)
        user = getpass.getuser()
        b = self.base
        lines = [
            "ClusterName=hpcwtest",
            "SlurmctldHost=localhost",
            f"SlurmUser={user}",
            f"SlurmdUser={user}",
            f"SlurmctldPort={_free_port()}",
            f"SlurmdPort={_free_port()}",
            "AuthType=auth/none",
            "CredType=cred/none",
            f"AuthInfo=cred_expire={self.cred_expire}",   # a requeued job may start again after this
            f"StateSaveLocation={b}/state",                # fresh: no jobs recovered from an old run
            f"SlurmdSpoolDir={b}/spool",
            f"SlurmctldPidFile={b}/slurmctld.pid",
            f"SlurmdPidFile={b}/slurmd.pid",
            f"SlurmctldLogFile={b}/log/slurmctld.log",
            f"SlurmdLogFile={b}/log/slurmd.log",
            "SlurmctldDebug=info",
            "SlurmdDebug=info",
            "ProctrackType=proctrack/linuxproc",
            "TaskPlugin=task/none",
            "SelectType=select/cons_tres",
            "SelectTypeParameters=CR_CPU",
            "SchedulerType=sched/backfill",
            "SchedulerParameters=bf_interval=1",
            "MpiDefault=none",
            "JobAcctGatherType=jobacct_gather/none",
            "AccountingStorageType=accounting_storage/none",
            "SlurmdParameters=config_overrides",           # claim CPUs the machine may not have
            "ReturnToService=2",
            "MailProg=/bin/true",
            "KillWait=5",
            "MinJobAge=600",                               # keep finished jobs visible to scontrol
            f"NodeName=localhost NodeAddr=127.0.0.1 CPUs={self.cpus} State=UNKNOWN",
            "PartitionName=debug Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=YES",
        ]
        with open(self.conf, "w") as f:
            f.write("\n".join(lines) + "\n")

    def start(self, timeout: float = 30.0) -> None:
        missing = [n for n, p in self.paths.items() if p is None]
        if missing:
            raise SlurmUnavailable(f"SLURM not installed (no {', '.join(missing)}): "
                                   f"run scripts/setup.sh as root or apt-get install {PACKAGES}")
        self.write_config()
        denv = dict(self.env)
        for name, args in (("slurmctld", ["-D", "-f", self.conf]),
                           ("slurmd", ["-D", "-f", self.conf, "-N", "localhost"])):
            out = open(os.path.join(self.base, "log", name + ".stdout"), "w")
            self.procs[name] = subprocess.Popen([self.paths[name], *args], env=denv, stdout=out,
                                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                                start_new_session=True)
            out.close()
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            dead = [n for n, p in self.procs.items() if p.poll() is not None]
            if dead:
                self.stop()
                raise SlurmUnavailable(f"{', '.join(dead)} exited at start-up: {self.log_tail(dead[0])}")
            r = self.run("sinfo", "-h", "-o", "%T", check=False)
            if r.returncode == 0 and r.stdout.split() == ["idle"]:
                return
            time.sleep(0.1)
        self.stop()
        raise SlurmUnavailable(f"node not idle after {timeout:.0f} s: {self.log_tail('slurmd')}")

    def log_tail(self, name: str, n: int = 5) -> str:
        lines = []
        for suffix in (".log", ".stdout"):
            try:
                with open(os.path.join(self.base, "log", name + suffix)) as f:
                    lines += f.read().splitlines()[-n:]
            except OSError:
                pass
        return " | ".join(lines[-n:]) or "(no log)"

    # -- clients ----------------------------------------------------------------
    def run(self, cmd: str, *args: str, check: bool = True, env: dict | None = None,
            timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([self.paths.get(cmd) or cmd, *args], env=env or self.env, check=check,
                              capture_output=True, text=True, timeout=timeout)

    def sbatch(self, script: str, args=(), options=(), env: dict | None = None, cwd: str | None = None) -> str:
        """Submit; returns the job id. env: extra variables exported to the job."""
        e = dict(self.env)
        e.update(env or {})
        r = subprocess.run([self.paths["sbatch"], "--parsable", *options, script, *args], env=e,
                           cwd=cwd, capture_output=True, text=True, timeout=60)
        if r.returncode != 0:
            raise RuntimeError(f"sbatch failed: {r.stderr.strip()}")
        return r.stdout.strip().split(";")[0]

    def job(self, jid: str) -> dict:
        """`scontrol show job -o` as a dict ({} once SLURM forgot the job)."""
        r = self.run("scontrol", "show", "job", "-o", jid, check=False)
        if r.returncode != 0:
            return {}
        out = {}
        for tok in r.stdout.split():
            k, sep, v = tok.partition("=")
            if sep and k not in out:
                out[k] = v
        return out

    def state(self, jid: str) -> str:
        """squeue's state (PENDING, RUNNING, ...); '' when the job has left the queue."""
        r = self.run("squeue", "-h", "-j", jid, "-o", "%T", check=False)
        return r.stdout.strip() if r.returncode == 0 else ""

    def wait_for(self, cond, timeout: float, what: str, step: float = 0.2):
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            v = cond()
            if v:
                return v
            time.sleep(step)
        raise TimeoutError(f"{what}: not after {timeout:.0f} s")

    def wait_gone(self, jid: str, timeout: float = 300) -> dict:
        """Poll squeue until the job left the queue (sbatch --wait polls too slowly); its final record."""
        self.wait_for(lambda: self.state(jid) == "", timeout, f"job {jid} to finish")
        return self.job(jid)

    def start_now(self, jid: str) -> None:
        """A requeued job waits until its credential expires (cred_expire); once that time has
        passed, start it at once instead of at the next scheduling pass."""
        info = self.job(jid)
        begin = info.get("StartTime", "")
        try:
            t = time.mktime(time.strptime(begin, "%Y-%m-%dT%H:%M:%S"))
            time.sleep(max(0.0, t - time.time() + 1.0))
        except ValueError:
            pass
        self.run("scontrol", "update", f"JobId={jid}", "StartTime=now", check=False)

    # -- tear-down --------------------------------------------------------------
    def stop(self) -> None:
        if self.procs.get("slurmctld") and self.procs["slurmctld"].poll() is None:
            r = self.run("squeue", "-h", "-o", "%A", check=False, timeout=20)
            jobs = r.stdout.split() if r.returncode == 0 else []
            if jobs:
                self.run("scancel", *jobs, check=False, timeout=20)
                t0 = time.monotonic()
                while time.monotonic() - t0 < 20 and self.run("squeue", "-h", check=False).stdout.strip():
                    time.sleep(0.2)
        for name in ("slurmd", "slurmctld"):
            p = self.procs.get(name)
            if p is None or p.poll() is not None:
                continue
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)
        self.procs.clear()
        self._kill_marked()

    def _kill_marked(self) -> None:
        """Last resort: processes started for this cluster (slurmstepd, job shells, ranks)
        carry HPCWEDGE_TEST_SLURM=<base> in their environment; end those by PID."""
        me = os.getpid()
        want = self.marker.encode()
        for d in os.listdir("/proc"):
            if not d.isdigit() or int(d) == me:
                continue
            try:
                with open(f"/proc/{d}/environ", "rb") as f:
                    if want not in f.read().split(b"\0"):
                        continue
            except OSError:
                continue
            if _alive(int(d)):
                try:
                    os.kill(int(d), signal.SIGKILL)
                except ProcessLookupError:
                    pass
