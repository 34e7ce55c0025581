"""Progress on stderr: a tqdm bar on a terminal, periodic plain lines in a batch log
(with an estimate of the time left); the memory guard of a run (run.max_memory_gb)."""
from __future__ import annotations

import bisect
import math
import os
import sys
import time

from hpcwedge.errors import UserError

GB = float(2 ** 30)
#: run.max_memory_gb = "auto": this fraction of the memory available when the run starts
#: (MemAvailable, plus what the process holds already), shared by the ranks on this host
AUTO_FRACTION = 0.8
#: a DD step copies the live rays and adds new ones: the guard asks for room for
#: this many times the rays' current bytes before the next step
DD_GROWTH = 3.0
#: a tree job's time left is told from how its decided share grew over the recent part of the
#: session: the last SHARE_WINDOW of the time since the job started, at least SHARE_WINDOW_MIN_S
#: (`ShareClock`), fitted as s = a + c tau^(1 - SHARE_DECAY) (tau: seconds since the job started; a
#: rate that falls as tau^-SHARE_DECAY, as a tree's does while the search goes deeper).
#: scripts/bench_eta.py (4 searches of 7-159 lines), median told / left 0.43-1.39 with
#: (0.2, 0.7); 0.32-0.48 with (0.2, 0), a steady rate, as before; 0.04-0.39 at the rate since the
#: start. Decay 0.9 told up to 12x too much, the last half (0.5, 0.7) 0.29 on one search
SHARE_WINDOW = 0.2
SHARE_DECAY = 0.7
SHARE_WINDOW_MIN_S = 20.0
#: ... and only once the share has grown this much in the job: before, a tree whose first tasks
#: opened its top levels has decided next to nothing (the curved neck m = 32 at 1 s: 3e-5 of
#: it, "about 11 h left" with 5 s to go)
SHARE_GROWTH_MIN = 0.01
#: the longest time left a ShareClock tells (seconds): a share that all but stalled
SHARE_LEFT_MAX_S = 1e8


class MemoryLimit(UserError):
    """The run would exceed run.max_memory_gb (one line, exit status 2)."""


def rss_bytes() -> int:
    """Resident memory of this process (/proc/self/statm; 0 where there is none)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def available_bytes() -> float:
    """Memory this process may still take: MemAvailable (/proc/meminfo), or the cgroup's
    memory.max less its usage when that is lower (a SLURM job's allocation); inf if unknown."""
    avail = float("inf")
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024.0
    except (OSError, ValueError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            cap = f.read().strip()
        with open("/sys/fs/cgroup/memory.current") as f:
            used = int(f.read())
        if cap != "max":
            avail = min(avail, float(int(cap) - used))
    except (OSError, ValueError):
        pass
    return avail


def ranks_on_host() -> int:
    """How many ranks of this MPI job share the host (1 outside mpirun)."""
    for key in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "SLURM_NTASKS_PER_NODE"):
        v = os.environ.get(key, "")
        if v.isdigit() and int(v) > 0:
            return int(v)
    return 1


def physical_bytes() -> float:
    """This machine's physical memory (inf where the system does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return math.inf


class MemoryGuard:
    """Refuses, in one line naming run.max_memory_gb, a run about to exceed its memory.

    limit_gb: a number, or "auto": AUTO_FRACTION of the memory available at start (plus
    the process's own), divided among `ranks_here` ranks on this host. check(need, what)
    raises MemoryLimit when the resident memory plus `need` more bytes exceeds it."""

    def __init__(self, limit_gb: float | str = "auto", ranks_here: int = 1):
        self.auto = limit_gb == "auto"
        self.ranks_here = max(1, ranks_here)
        if self.auto:
            self.limit = AUTO_FRACTION * (available_bytes() + rss_bytes() * ranks_here) / max(1, ranks_here)
        else:
            self.limit = float(limit_gb) * GB

    def check(self, need: float, what: str) -> None:
        rss = rss_bytes()
        if rss + need <= self.limit:
            return
        share = "" if self.ranks_here == 1 else f", shared by its {self.ranks_here} ranks"
        whose = (f"run.max_memory_gb = \"auto\" ({self.limit / GB:.3g} GB: {AUTO_FRACTION:.0%} of this "
                 f"machine's available memory{share})" if self.auto else f"run.max_memory_gb = {self.limit / GB:.3g}")
        raise MemoryLimit(f"run.max_memory_gb: {what}: about {(rss + need) / GB:.3g} GB needed "
                          f"({rss / GB:.3g} GB in use), more than {whose}; stopped before it runs out "
                          "(no result written; a checkpoint already written keeps its work): raise "
                          "run.max_memory_gb if the machine has the memory (--resume then goes on), "
                          "or run a smaller scene (fewer contact nodes, mu nearer mu^c)")

    def dd_step(self, info: dict, where: str = "") -> None:
        """After a DD step (dd.complementary_rays progress: "rays", "bytes", "done", "total"):
        room for DD_GROWTH times the live rays' bytes."""
        if "bytes" in info:
            self.check(DD_GROWTH * info["bytes"],
                       f"the double description{where} holds {info['rays']:,} live rays "
                       f"({info['bytes'] / GB:.3g} GB) after {info['done']} of {info['total']} "
                       "constraints and grows")


def out_of_memory(where: str) -> MemoryLimit:
    """The one-line error of a MemoryError that still happened (in `where`)."""
    return MemoryLimit(f"run.max_memory_gb: out of memory in {where} ({rss_bytes() / GB:.3g} GB "
                       "in use when it struck; nothing written): run a smaller scene, or on a machine "
                       "with more memory")


class Progress:
    """Callable taking the engines' progress dicts ({"done", "total", "rays", "elapsed"}).

    On a terminal: a tqdm bar per stage. Otherwise (batch logs): one line every
    `every` seconds and one at the end of each stage. quiet=True: nothing.
    """

    def __init__(self, quiet: bool = False, every: float = 10.0, stream=None):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        #: MemoryGuard checked at every DD step (set by the pipeline), quiet or not
        self.guard: MemoryGuard | None = None
        self.every = every
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.label = ""
        self._bar = None
        self._last = 0.0

    def stage(self, label: str) -> "Progress":
        self.close()
        self.label = label
        self._last = time.monotonic()
        return self

    def __call__(self, info: dict) -> None:
        if self.guard is not None:
            self.guard.dd_step(info)
        if self.quiet:
            return
        done, total = info.get("done", 0), info.get("total", 0)
        if self.tty:
            if self._bar is None:
                from tqdm import tqdm
                self._bar = tqdm(total=total, desc=self.label, unit="constraint",
                                 file=self.stream, leave=False)
            self._bar.n = done
            self._bar.set_postfix(rays=info.get("rays"), refresh=False)
            self._bar.refresh()
            return
        now = time.monotonic()
        if now - self._last >= self.every or done == total:
            self._last = now
            elapsed = info.get("elapsed", 0.0)
            # the rays so far (the last count is the run's, in show's words: pipeline.rays)
            so_far = f"{info.get('rays', 0)} rays so far, " if done < total else ""
            print(f"[hpcwedge] {self.label}: {done}/{total} constraints, "
                  f"{so_far}{elapsed:.1f} s{eta(elapsed, done, total)}",
                  file=self.stream, flush=True)

    def note(self, text: str) -> None:
        if not self.quiet:
            self.close()
            print(f"[hpcwedge] {text}", file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def eta(elapsed: float, done: int, total: int) -> str:
    """", about N s left" at the rate so far (empty before the first unit or at the end)."""
    if done <= 0 or done >= total:
        return ""
    return left_text(elapsed / done * (total - done))


def left_text(seconds: float | None) -> str:
    """", about N s left" (N min from 120 s on, N h from 2 h on); empty for None."""
    if seconds is None:
        return ""
    if seconds < 120:
        return f", about {seconds:.0f} s left"
    return f", about {seconds / 60:.0f} min left" if seconds < 7200 else f", about {seconds / 3600:.0f} h left"


class ShareClock:
    """The time a share in [0, 1] that grows to 1 (a tree job's decided share) still needs:
    s = a + c tau^q (q = 1 - decay, tau the seconds since t0) through the sample now and the
    last one at or before the window's start (the last `window` of tau, at least `min_s`
    seconds; the first sample if none), extrapolated to s = 1. decay = 0 is the steady rate
    over the window. A tree's share grows fast while the easy subtrees close and ever slower in
    the hard ones, so a steady rate tells too little time (plug3d 6 x 8 at 1.1 mu^c, 92 %
    decided: "about 30 s left" at the rate since the start, with ~10 min to go).

    ShareClock(t0, share0) starts it (seconds, any clock); left(t, share) records a sample and
    returns the seconds left (at most SHARE_LEFT_MAX_S), or None while the share has grown
    less than SHARE_GROWTH_MIN since the start, or did not grow over the window. A resumed job
    keeps its clock (ShareClock.resumed): tau counts from the job's start in its first session."""

    def __init__(self, t0: float, share0: float, window: float = SHARE_WINDOW,
                 min_s: float = SHARE_WINDOW_MIN_S, decay: float = SHARE_DECAY):
        if not 0.0 <= decay < 1.0:
            raise ValueError(f"decay {decay} outside [0, 1)")
        self.window, self.min_s, self.q = window, min_s, 1.0 - decay
        self._t, self._share = [t0], [share0]

    @classmethod
    def resumed(cls, t: float, before_s: float, share: float, **settings) -> "ShareClock":
        """The clock of a job resumed at t with before_s seconds of work in its earlier sessions
        and `share` decided: started at t - before_s with nothing decided (its samples in
        between are gone), with the sample (t, share)."""
        clock = cls(t - before_s, 0.0, **settings)
        clock.left(t, share)
        return clock

    def left(self, t: float, share: float) -> float | None:
        if t >= self._t[-1]:
            self._t.append(t)
            self._share.append(share)
        t0 = self._t[0]
        span = max(self.min_s, self.window * (t - t0))
        # the last sample at or before the window's start (the first sample if none)
        i = max(0, bisect.bisect_right(self._t, t - span) - 1)
        grown = share - self._share[i]
        if t <= self._t[i] or grown <= 0.0 or share - self._share[0] < SHARE_GROWTH_MIN:
            return None
        q, tau, tau_i = self.q, t - t0, self._t[i] - t0
        c = grown / (tau ** q - tau_i ** q)                # s = a + c tau^q through both samples
        end_q = tau ** q + max(0.0, 1.0 - share) / c       # tau_end^q
        return min(SHARE_LEFT_MAX_S, max(0.0, math.exp(min(math.log(end_q) / q, 40.0)) - tau))
