"""The certified lower bound on the global mu^c (mu_c.lower_bound) against brute force on small
random free bodies, against tan(taper) on the free plugs, and its exact check against tampered
certificates."""
from __future__ import annotations

import math

import numpy as np
import pytest
from instances import plug3d_param, random_problem, random_problem_3d

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.lower_bound import bound_at, equilibrium_rows, rigid_bound, verified
from hpcwedge.reference import bisect, brute_force_patterns

MU_HI = 20.0


def brute_global_mu_c(p, m: int) -> float | None:
    """The global mu^c by bisection on "some full pattern is feasible" (2^m solves a step),
    to 1e-6: the upper end of the bracket; None without a wedge at MU_HI."""
    if not brute_force_patterns(p, m, MU_HI):
        return None
    return bisect(lambda mu: bool(brute_force_patterns(p, m, mu)), 0.0, MU_HI, 1e-6)


@pytest.mark.parametrize("dim,make", [(2, random_problem), (3, random_problem_3d)])
def test_bound_never_exceeds_the_brute_force_global_mu_c(dim, make):
    """Random free bodies (m = 4): the certified bound L lies at or below the global mu^c
    found by brute force, and no full pattern is feasible at L (1 - 1e-6); the bound is not
    vacuous (L > 0 on most bodies: the normals point into the body)."""
    positive = 0
    for seed in range(8):
        prob = make(np.random.default_rng(100 + seed), 4, True)
        p, m = parametrize(prob), prob.m
        L, solves = rigid_bound(p, m, MU_HI, rtol=1e-8)
        assert solves >= 1 and 0.0 <= L <= MU_HI
        bf = brute_global_mu_c(p, m)
        if bf is not None:
            assert L <= bf, (seed, L, bf)
        if L > 0:
            positive += 1
            assert brute_force_patterns(p, m, L * (1 - 1e-6)) == []
    assert positive >= 4


def plug2d_param(rows: int, taper_deg: float):
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    prob = contact_problem(parse_scene({"name": "p", "dim": 2, "friction": {"mu": [1.0]},
                                        "model": {"kind": "plug2d", "rows": rows, "taper_deg": taper_deg}}))
    return parametrize(prob), prob.m


@pytest.mark.parametrize("body,taper", [("plug2d", 10.0), ("plug2d", 25.0), ("plug3d", 10.0), ("plug3d", 3.0)])
def test_bound_on_free_plugs_is_tan_taper(body, taper):
    """Free plugs (SPEC §6: mu^c = tan(taper), set by the rigid body): the bound is tan(taper)
    to 1e-9, certified just below it and not just above."""
    p, m = plug2d_param(6, taper) if body == "plug2d" else plug3d_param(2, 6, taper_deg=taper)
    want = math.tan(math.radians(taper))
    L, _ = rigid_bound(p, m, 1.0, rtol=1e-11)
    assert abs(L - want) <= 1e-9 * want
    assert bound_at(p, m, want * (1 - 1e-9)).certified
    assert not bound_at(p, m, want * (1 + 1e-9)).certified


@pytest.mark.parametrize("body", ["plug2d", "plug3d"])
def test_a_body_wedged_at_every_mu_has_bound_zero_in_few_solves(body):
    """A plug at a 0 deg taper (mu^c = 0): no bound above 0 certifies, and the bisection
    ends where hi <= rtol mu_hi (~34 halvings from 100 at 1e-10) with 0.0, instead of
    halving until mid underflows to 0 (bound_at None: an AttributeError)."""
    p, m = plug2d_param(4, 0.0) if body == "plug2d" else plug3d_param(2, 5, taper_deg=0.0)
    L, solves = rigid_bound(p, m, 100.0)
    assert L == 0.0 and solves <= 40
    assert not bound_at(p, m, 1e-8).certified


def test_tampered_certificates_are_rejected():
    """plug3d 2 x 6: the certificate found at tan 10 deg (1 - 1e-9) passes the exact check;
    the same w at a mu past the bound, w perturbed by 1e-7, and -w fail it; and the check
    decides within 1e-12 of the certificate's own threshold, far inside the solver's
    tolerance."""
    p, m = plug3d_param(2, 6)
    G = equilibrium_rows(p)
    mu = math.tan(math.radians(10)) * (1 - 1e-9)
    b = bound_at(p, m, mu)
    assert b.certified and verified(G, m, 3, mu, b.w)
    assert not verified(G, m, 3, mu * (1 + 2e-9), b.w)
    rng = np.random.default_rng(0)
    assert not verified(G, m, 3, mu, b.w + 1e-7 * np.linalg.norm(b.w) * rng.standard_normal(b.w.shape))
    assert not verified(G, m, 3, mu, -b.w)
    # the exact threshold of this w is the least node ratio g_n / ||g_t|| (tan 10 deg up to
    # the solver's 1e-10): the check decides 1e-12 on either side of it
    g = G @ b.w
    top = float(np.min(g[:m] / np.hypot(g[m:2 * m], g[2 * m:])))
    assert verified(G, m, 3, top * (1 - 1e-12), b.w)
    assert not verified(G, m, 3, top * (1 + 1e-12), b.w)
