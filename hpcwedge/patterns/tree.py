"""Sign-pattern branch and bound (2D: LP relaxations, 3D: SOCP relaxations): the tree
(PatternTree), its unit of work (Subtree) and counters (BnBStats).

A node of the tree fixes some nodes to contact (u_n = 0) or gap (r = 0); the
relaxation keeps u_n >= 0, r_n >= 0 (and friction) for the others. A child
whose condition the parent's solution already meets is feasible without a
solve (2D: the LP vertex meets it to MEETS_TOL; 3D: the interior-point
solution meets it to NEAR_TOL, and its projection onto the child's equalities
verifies on every row of the child, socp.VERIFY_TOL). Undecided statuses keep
the subtree (never pruned on doubt); an undecided full pattern is reported in
`found` and listed again in `Explored.undecided`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from hpcwedge.contact.problem import Parametrization, blocks
from hpcwedge.nodesets import bits_to_mask, bits_to_nodes, to_bits
from hpcwedge.parallel.cancel import TaskCancelled, task_stopping
from hpcwedge.patterns.symmetry import Symmetry
from hpcwedge.results.record import TreeStats
from hpcwedge.solvers.feasibility import TREE_OPTIONS, Decision, SolverOptions, decide
from hpcwedge.solvers.lp import TreeLp, lp_violation
from hpcwedge.solvers.rows import ConeRows, Status, count, pattern_rows, problem_dim
from hpcwedge.solvers.screens import PyramidScreens
from hpcwedge.solvers.socp import verified

MEETS_TOL = 1e-12
#: 2D: a full pattern whose LP point violates a unit row by more than this (HiGHS points of
#: clearly feasible patterns: <= 3e-16; at mu = mu^c (1 - 1e-9): 3e-14) is feasible
#: only to HiGHS's tolerance: counted as statuses["near_boundary"] (pipeline: suspect)
NEAR_BOUNDARY_TOL = 1e-14
#: 3D: a child's condition counts as nearly met by the parent's x below this
#: (relative to max |u|, |r|); the projected point must then verify
NEAR_TOL = 1e-6


@dataclass
class BnBStats:
    """solves: feasibility problems solved (3D: SOCPs); lps: linear programs solved
    besides (3D: screens and pyramid fallbacks); skipped: tree nodes decided by the
    parent's solution; pruned: tree nodes ruled out without a solve (no rule does so: 0,
    kept as a counter of the result); undecided: solves that decided nothing (kept); nodes: tree
    nodes visited; statuses: how each solve was decided (feasibility.decide counts)."""

    solves: int = 0
    skipped: int = 0
    pruned: int = 0
    undecided: int = 0
    nodes: int = 0
    lps: int = 0
    extra: dict = field(default_factory=dict)
    statuses: dict = field(default_factory=dict)

    def add(self, other: "BnBStats") -> None:
        for k in ("solves", "skipped", "pruned", "undecided", "nodes", "lps"):
            setattr(self, k, getattr(self, k) + getattr(other, k))
        for k, v in other.statuses.items():
            self.statuses[k] = self.statuses.get(k, 0) + v


@dataclass(frozen=True)
class Subtree:
    """A partial sign pattern: `depth` nodes are fixed (with a static order the
    first `depth` of it; with dynamic branching any `depth` nodes), node i to
    contact when bit i of `contact` is set, to gap when bit i of `gap` is set. Small and picklable: the unit of work the parallel layer
    moves around and the checkpoint stores (three integers)."""

    depth: int
    contact: int = 0
    gap: int = 0

    def masks(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(zero_u, zero_r) boolean masks over the m nodes (views of one array)."""
        w = -(-m // 8) * 8                      # both from one unpacking, gap from bit w on
        both = bits_to_mask(self.contact & ((1 << m) - 1) | self.gap << w, 2 * w)
        return both[:m], both[w:w + m]


@dataclass
class Explored:
    """What one call of PatternTree.explore produced: the feasible full
    patterns found, the roots of the subtrees left open (budget spent), stats."""

    found: list[Subtree]
    open: list[Subtree]
    stats: BnBStats
    undecided: list[Subtree] = field(default_factory=list)   # found patterns no solver decided
    #: per open subtree, the parent's point that proves its root feasible (or None): passed
    #: back to explore(..., x=), the root is decided as in one uninterrupted pass (no solve,
    #: the same branching node), so every counter is the same however the tree is split
    open_x: list = field(default_factory=list)
    #: the search stopped early because the engine asked it to (parallel.task_stopping)
    stopped: bool = False


class PatternTree:
    """The sign-pattern search tree of one problem at one mu, explored by
    subtrees: a pure function of (problem, mu, order), resumable from any set
    of open subtree roots. The dimension (2: LPs, 3: SOCPs) comes from the
    parametrisation. Node order: `order`; default 0..m-1 in 2D and m-1..0 in 3D.

    3D order by measurement (scripts/bench_3d_order.py, results/bench_3d_order.json:
    plug3d 2x5 and 3x4 at mu 0.65 and 1, four random bodies with m = 8): natural,
    reversed, interleaved (0, m-1, 1, ...) and by single-node coupling |k_tn|/k_nn
    (ascending, descending) stay within 15 % of each other in SOCP count; reversed
    needed the fewest in total (7,910 against 8,144 natural, 8,271 coupling
    ascending, 8,641 interleaved, 9,338 coupling descending) and the fewest in 7
    of the 10 cases. The order changes the work, never the patterns found.

    3D with friction and `order=None` branches dynamically instead (the default):
    on the free node whose relaxed solution violates complementarity most
    (`_branch_node`; scripts/bench_socp_count.py, results/bench_socp_count.json).
    A given `order` keeps the static order with steered solves. branch="reaction" takes
    instead the free node of largest relaxed r_n (its gap child is the likeliest to fail): a
    tree that proves no pattern feasible near mu^c is smaller so (curved neck 4 x 8 at
    mu^c (1 + 1e-9): 1,945 nodes instead of 3,393; the global search's trees use it).

    With a `symmetry` group (symmetry.py; the feasible patterns are invariant
    under it) the tree branches on orbits (orbital branching): at a tree node
    with stabiliser H (the elements fixing its contact and gap sets) and branching
    node i, the children are "i in contact" and "the whole H-orbit of i in gap".
    Every orbit of feasible patterns keeps a representative among the leaves
    (a pattern below the node with some j of the orbit in contact is mapped by the
    h in H with h(j) = i into the first child; otherwise it lies in the second);
    `expand` gives back all of them.

    Each child also gets orbital fixing (Ostrowski, Linderoth, Rossi and Smriglio,
    "Orbital branching", 2011): every free node whose orbit under the stabiliser of the
    child's contact set alone (a larger group than H) meets its gap set is put in gap too.
    A pattern P dropped by it, with such a node j in contact, has an image h(P) (h fixing
    the contact set, h(j) in the gap set) that agrees with every contact fixing on the
    path from the root and breaks a gap fixing; at the highest node where it first does
    so, either a branching put an orbit in gap, and an element of that node's H maps
    h(P) into its contact child, or an orbital fixing dropped it, and the same holds
    there (induction on depth): the orbit is represented in a contact child to the left
    of the path, and moving left ends at a leaf. plug3d 3 x 6 at mu = 1: 5,293 SOCPs and
    467 leaves instead of 8,375 and 831, the same 3,796 patterns; the fixing is a
    function of the node alone, so the tree and its counters stay split-invariant.

    3D with friction and `screens` (`run.screens`): nodes with at least 40 % of the nodes
    fixed are first put to two pyramid LPs (screens.PyramidScreens), and only a node that
    neither decides gets a SOCP (plug3d 3 x 6 at mu 0.65 without symmetry: 855 SOCPs for
    127 patterns instead of 7,219, in the same time). Off by default: measured on plug3d up to
    m = 24, the screens cost 0.90-1.34x the CPU time, median 1.12x (docs/benchmarks.md,
    scripts/bench_flags.py)."""

    def __init__(self, param: Parametrization, m: int, mu: float, friction: bool = True,
                 order: list[int] | None = None, symmetry: Symmetry | None = None,
                 options: SolverOptions = TREE_OPTIONS, screens: bool = False, branch: str = "violation",
                 lp_chain: bool = False):
        if branch not in ("violation", "reaction"):
            raise ValueError(f"branch: 'violation' or 'reaction', got {branch!r}")
        self.param, self.m, self.mu, self.friction, self.branch = param, m, mu, friction, branch
        #: the solver options of every solve (3D: long steps by default; DEFAULT_OPTIONS for
        #: a search near mu^c, global_mu_c, where long steps left nodes undecided)
        self.options = options
        self.symmetry = symmetry if symmetry is not None and symmetry.order > 1 else None
        self.dim = problem_dim(param, m)
        #: 3D with friction and no order given: the node branched on is chosen from the
        #: relaxed solution (explore); otherwise the static order below
        self.dynamic = self.dim == 3 and friction and order is None
        if order is None:
            order = list(range(m - 1, -1, -1)) if self.dim == 3 else list(range(m))
        self.order = list(order)
        #: 3D, static order: each solve minimises the next node's u_n (see explore)
        self.steer = self.dim == 3 and friction and not self.dynamic
        U = blocks(param.U, m, self.dim)[0]
        self._steer = U / np.maximum(np.linalg.norm(U, axis=1, keepdims=True), 1e-300)
        #: 3D with friction and screens: LP screens before the SOCPs of deep nodes (screens.py)
        self._screens = PyramidScreens(param, m, mu) if screens and self.dim == 3 and friction else None
        #: 2D with friction: the nodes' LPs in one warm HiGHS model (lp.TreeLp; decide on doubt)
        #: lp_chain: each LP from the last one's basis (TreeLp's chain: one process's dive only)
        self._lp = TreeLp(param, m, mu, lp_chain) if self.dim == 2 and friction and 0.0 < mu < np.inf else None

    def root(self) -> Subtree:
        return Subtree(0)

    def explore(self, subtree: Subtree, budget: int | None = None,
                first_only: bool = False, x: np.ndarray | None = None) -> Explored:
        """Depth-first from `subtree`, contact before gap, for at most `budget`
        tree nodes (None: to the end). Returns found patterns in discovery order
        and the open subtrees (their union with the explored part is `subtree`),
        each with its witness (Explored.open_x; give it back as `x`).

        Stops early, handing back the rest as open like a spent budget, when the
        engine asks (parallel.task_stopping: a SIGTERM, a master's stop; checked
        between tree nodes, and inside a solve, which then hands its node back open).

        3D: the SOCP of a tree node minimises u_n of the node branched on next;
        its optimum lies on u_n = 0 when the contact child is feasible (the
        skip-solve rule takes it, after verification), and a verified dual that
        proves min u_n > 0 rules the contact child out without a solve."""
        mu = self.mu if self.friction else 0.0
        stats = BnBStats()
        found: list[Subtree] = []
        undecided: list[Subtree] = []
        stack = [(subtree, x)]
        stopped = False
        while stack:
            if budget is not None and stats.nodes >= budget:
                break
            if task_stopping():
                stopped = True
                break
            node, x = stack.pop()
            before = (replace(stats, statuses=dict(stats.statuses), extra=dict(stats.extra)),
                      len(found), len(undecided), x)
            try:
                stats.nodes += 1
                doubt = no_contact = False
                if x is None:
                    dec = self._solve(node, mu, stats)
                    if dec.status == Status.INFEASIBLE:
                        continue
                    if dec.status == Status.UNDECIDED:
                        stats.undecided += 1
                        doubt = True
                    x, no_contact = dec.x, dec.positive
                else:
                    stats.skipped += 1
                if node.depth == self.m:
                    self._leaf(node, x, doubt, mu, stats, found, undecided)
                    if first_only:
                        stack.clear()
                        break
                    continue
                stack.extend(reversed(self._children(node, x, no_contact, mu, stats)))
            except TaskCancelled:
                # a solve cut short by the stop (conic: Clarabel asks task_stopping every
                # iteration): the node goes back open, as if not visited, so no count changes
                stats, n_found, n_undecided, x = before
                del found[n_found:], undecided[n_undecided:]
                stack.append((node, x))
                stopped = True
                break
        stats.lps = stats.statuses.get("lp_calls", 0) + stats.statuses.get("screen_lps", 0)
        rest = stack[::-1]
        return Explored(found, [node for node, _ in rest], stats, undecided,
                        open_x=[w for _, w in rest], stopped=stopped)

    def _solve(self, node: Subtree, mu: float, stats: BnBStats) -> Decision:
        """The decision of `node`'s relaxation: the LP screens when they apply and decide,
        else a solve (3D, static order: steered to the next node's u_n)."""
        zu, zr = node.masks(self.m)
        if self._lp is not None:
            status, x = self._lp.solve(zu, zr, stats.statuses)
            if status != Status.UNDECIDED:
                stats.solves += 1
                return Decision(status, x)
        rows = pattern_rows(self.param, self.m, zu, zr, self.friction)
        if self._screens is not None and self._screens.applies(zu, zr):
            dec = self._screens.decide(rows, zu, zr, stats.statuses)
            if dec is not None:
                return dec
        stats.solves += 1
        steer = self._steer[self._static_next(node)] if node.depth < self.m and self.steer else None
        return decide(rows, mu, self.options, stats.statuses, objective=steer)

    def _leaf(self, node: Subtree, x: np.ndarray | None, doubt: bool, mu: float, stats: BnBStats,
              found: list[Subtree], undecided: list[Subtree]) -> None:
        """A feasible full pattern: into `found` (and `undecided` on doubt); 2D, a point
        feasible only to HiGHS's tolerance is counted as statuses["near_boundary"]."""
        found.append(node)
        if doubt:
            undecided.append(node)
        elif self.dim == 2 and self.friction and self._near_boundary(node, x, mu):
            count(stats.statuses, "near_boundary")

    def _children(self, node: Subtree, x: np.ndarray | None, no_contact: bool, mu: float,
                  stats: BnBStats) -> list[tuple[Subtree, np.ndarray | None]]:
        """The children of an inner node whose relaxed point is x (None: undecided), contact
        child first (left out when `no_contact`: the parent proved min u_n > 0), each with
        the point that proves it feasible without a solve, or None."""
        pt = None if x is None else RelaxedPoint.of(self.param, x)
        i = self._branch_node(node, pt)
        orbit = [i] if self.symmetry is None else \
            self.symmetry.stabilizer(node.contact, node.gap).orbit(i).tolist()
        kids = []
        for contact in (True, False):
            if contact and no_contact:
                count(stats.statuses, "contact_child_infeasible_by_parent")
                continue
            kc = node.contact | (1 << i) if contact else node.contact
            kg = node.gap if contact else node.gap | to_bits(orbit)
            kg |= self._orbital_fixing(kc, kg)
            contacts = [i] if contact else []
            gaps = list(bits_to_nodes(kg & ~node.gap, self.m))
            kid = Subtree(node.depth + len(contacts) + len(gaps), kc, kg)
            kids.append((kid, None if pt is None else self._witness(kid, pt, contacts, gaps, mu)))
        return kids

    def _near_boundary(self, node: Subtree, x: np.ndarray, mu: float) -> bool:
        """2D: the full pattern's LP point x violates a row by more than NEAR_BOUNDARY_TOL."""
        zu, zr = node.masks(self.m)
        return lp_violation(pattern_rows(self.param, self.m, zu, zr), mu, x) > NEAR_BOUNDARY_TOL

    def _static_next(self, node: Subtree) -> int:
        """The first node of `order` not fixed in `node`."""
        fixed = node.contact | node.gap
        return next(i for i in self.order if not fixed >> i & 1)

    def _branch_node(self, node: Subtree, pt: RelaxedPoint | None) -> int:
        """The free node to branch on. Static: the next one in `order`. Dynamic (3D):
        the free node whose relaxed solution pt violates complementarity most,
        min(u_n,i / max|u_n|, |r_i| / max|r|) (branch="reaction": of largest r_n,i), ties and
        pt = None (undecided solve) by
        `order`: a function of (node, x), so the tree is deterministic."""
        if not self.dynamic or pt is None:
            return self._static_next(node)
        m = self.m
        fixed = node.contact | node.gap
        free = [i for i in self.order if not fixed >> i & 1]
        if self.branch == "reaction":
            return max(free, key=pt.rx[:m].tolist().__getitem__)
        u = pt.ux[:m]
        r2 = pt.rx[:3 * m].reshape(3, m) ** 2
        r = np.sqrt(r2[0] + r2[1] + r2[2])
        v = np.minimum(np.maximum(u, 0) / max(np.abs(u).max(), 1e-300), r / max(r.max(), 1e-300)).tolist()
        return max(free, key=v.__getitem__)          # first maximum in `order`

    def expand(self, found: list[Subtree]) -> list[Subtree]:
        """expand_orbits with this tree's symmetry."""
        return expand_orbits(found, self.symmetry, self.m)

    def _orbital_fixing(self, contact: int, gap: int) -> int:
        """Orbital fixing (class doc): the free nodes whose orbit under the stabiliser of the
        contact set alone meets the gap set, as bits; 0 without a symmetry."""
        if self.symmetry is None or not gap:
            return 0
        reach = int(np.bitwise_or.reduce(self.symmetry.stabilizer(contact, 0).images(gap)))
        return reach & ~(contact | gap)

    def _witness(self, kid: Subtree, pt: RelaxedPoint, contacts: list[int], gaps: list[int],
                 mu: float) -> np.ndarray | None:
        """The parent's point pt.x, or a point derived from it, that proves `kid` (whose
        newly fixed nodes are `contacts` and `gaps`) feasible; None if it does not."""
        param, m, x = self.param, self.m, pt.x
        new = [(i, True) for i in contacts] + [(i, False) for i in gaps]
        if self.dim == 2:
            return x if all(pt.meets(m, i, c) for i, c in new) else None
        if not all(pt.meets(m, i, c, NEAR_TOL, dim=3) for i, c in new):
            return None
        zu, zr = kid.masks(m)
        rows = pattern_rows(param, m, zu, zr, self.friction)
        if not isinstance(rows, ConeRows):             # friction=False: an LP, no projection at hand
            return None
        return verified(rows, mu, rows.Z @ (rows.Z.T @ x))


def expand_orbits(found: list[Subtree], symmetry: Symmetry | None, m: int) -> list[Subtree]:
    """All patterns of the orbits of the full patterns `found` under `symmetry`
    (found itself without one), sorted by (contact, gap) bits."""
    if symmetry is None or symmetry.order == 1:
        return list(found)
    return [Subtree(m, c, g) for c, g in symmetry.expand([(s.contact, s.gap) for s in found])]


def sign_patterns(param: Parametrization, m: int, mu: float, friction: bool = True,
                  first_only: bool = False, stats: BnBStats | None = None,
                  order: list[int] | None = None, symmetry: Symmetry | None = None,
                  representatives: bool = False,
                  options: SolverOptions = TREE_OPTIONS) -> list[tuple[np.ndarray, np.ndarray]]:
    """Feasible full patterns (zero_u, zero_r) at mu, serially: depth first, in
    contact-before-gap order at each level; with a symmetry, every orbit's
    patterns sorted by (contact, gap) bits — or, with representatives=True (and
    first_only), only the leaves the tree found: one or more per orbit. options: as
    PatternTree's."""
    tree = PatternTree(param, m, mu, friction, order, symmetry, options=options)
    out = tree.explore(Subtree(0), first_only=first_only)
    if stats is not None:
        stats.add(out.stats)
    found = out.found if first_only or representatives else tree.expand(out.found)
    return [node.masks(m) for node in found]


@dataclass(frozen=True)
class RelaxedPoint:
    """A tree node's relaxed point x with ux = U x, rx = R x and scale = max(|U x|, |R x|),
    formed once for the branching rule and both children's witness tests."""

    x: np.ndarray
    ux: np.ndarray
    rx: np.ndarray
    scale: float

    @classmethod
    def of(cls, param: Parametrization, x: np.ndarray) -> "RelaxedPoint":
        ux, rx = param.U @ x, param.R @ x
        return cls(x, ux, rx, max(np.abs(ux).max(), np.abs(rx).max(), 1e-300))

    def meets(self, m: int, i: int, contact: bool, tol: float = MEETS_TOL, dim: int = 2) -> bool:
        """Node i's contact (u_n,i = 0) or gap (r_i = 0) condition holds here, to tol
        relative to `scale`."""
        if contact:
            return abs(self.ux[i]) <= tol * self.scale
        return max(abs(self.rx[k * m + i]) for k in range(dim)) <= tol * self.scale


# ---------------------------------------------------------------- the "subtree" task of the engine


class PatternContext:
    """What a worker needs to explore subtrees: make_tree(mu) -> a tree with
    root() and explore(subtree, budget) (PatternTree), and the mu list."""

    def __init__(self, make_tree, mus):
        self.make_tree, self.mus = make_tree, list(mus)
        self._trees = {}

    def tree(self, i: int):
        """The tree at mus[i], made on first use (each worker makes its own)."""
        if i not in self._trees:
            self._trees[i] = self.make_tree(self.mus[i])
        return self._trees[i]

    def __getstate__(self):
        return {"make_tree": self.make_tree, "mus": self.mus, "_trees": {}}


#: the counters of a subtree task that do not depend on the split of the work: stats.bnb's
STAT_KEYS = tuple(f.name for f in fields(TreeStats) if f.name != "partitions")
#: a subtree task's counter of how solves were decided: STATUS_PREFIX + feasibility's key
STATUS_PREFIX = "status_"


def explore_task(ctx: PatternContext, payload):
    """Task "subtree": payload (mu index, Subtree, budget, witness x or None) ->
    (found, open, stats dict, undecided found, open witnesses). Stopped by the
    engine (task_stopping), it returns what it found and hands the rest back as open."""
    i, subtree, budget, x = payload
    out = ctx.tree(i).explore(subtree, budget, x=x)
    stats = {k: getattr(out.stats, k) for k in STAT_KEYS}
    for k, v in (getattr(out.stats, "statuses", None) or {}).items():
        stats[STATUS_PREFIX + k] = v
    return out.found, out.open, stats, list(getattr(out, "undecided", [])), list(out.open_x)


def solver_statuses(counters: dict) -> dict:
    """{status: count} of a patterns job's counters STATUS_PREFIX + status (how each solve
    was decided: explore_task's), in the counters' order."""
    return {k[len(STATUS_PREFIX):]: v for k, v in counters.items() if k.startswith(STATUS_PREFIX)}
