"""One robust least-squares fit of every cue: the camera, its spread, the cue that fixed it.

Residual blocks, each normalised by its one-sigma noise (so the robust loss sees sigmas):

- ``flow``: road points' observed minus predicted position in the later frame of each pair
  (:mod:`vid2sim.calib.groundmotion`), two rows per point;
- ``GPS speed`` / ``GPS yaw``: each pair's forward motion and heading change against the
  GPS's on the video clock;
- ``vanishing point``: the lane segments' vanishing point against where the vehicle's
  forward direction projects;
- ``lane width``: the ego lane's measured width in camera heights against the named prior
  width (or the map's);
- ``plumb lines``: straight edges' distances from their straight lines;
- ``motion prior`` (slip, body pitch) and ``prior`` (the camera before the data).

Solved with ``scipy.optimize.least_squares`` (trust-region reflective, sparse
finite-difference Jacobian; measurement residuals soft-L1 beyond two sigmas, priors
quadratic) and points whose residual
exceeds a few robust sigmas of their pair dropped between rounds. The covariance is the
sandwich ``A^-1 B A^-1`` with ``B`` summed over independent units (a pair's points share
their errors, as do a chain's), so the spread follows the real scatter of the pairs and not
the count of points. A parameter that the data alone (without the ``prior`` rows) do not
give to a useful one-sigma (:class:`~vid2sim.calib.CalibrationConfig`) is reported as not
observable in the clip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vid2sim.calib import cameramodel as geo
from vid2sim.calib.groundmotion import GLOBALS, PAIR_PARAMS, G, P, PairSet, predict_b, unpack
from vid2sim.calib.lines import plumb_residuals

if TYPE_CHECKING:
    from scipy.sparse import lil_matrix

NG, NP = len(GLOBALS), len(PAIR_PARAMS)
#: Where the globals may go: a focal length of 0.1-20 image widths' worth of ln, a lens
#: whose radial model stays monotonic over a normalised radius of 0.9 (|k1| <= 0.6), mount
#: angles within 30 deg, a height of 0.3-5 m. Beyond them the model folds or is no camera.
GLOBAL_BOUNDS = (np.array([math.log(1.0), -0.6, -0.3, -0.52, -0.52, -0.52, math.log(0.3)]),
                 np.array([math.log(1e5), 0.6, 0.3, 0.52, 0.52, 0.52, math.log(5.0)]))


@dataclass(slots=True)
class Problem:
    """What the fit sees (all optional but the principal point and the prior)."""

    c: np.ndarray
    prior_mean: np.ndarray  # (NG,)
    prior_std: np.ndarray  # (NG,), inf: none
    fixed: np.ndarray  # (NG,) bool: held at prior_mean (a camera file's value)
    pairs: PairSet | None = None
    flow_noise_px: float = 0.5
    gps_d: np.ndarray | None = None  # (K,) NaN where unknown
    gps_d_std: np.ndarray | None = None
    gps_dpsi: np.ndarray | None = None
    gps_dpsi_std: np.ndarray | None = None
    motion_std: np.ndarray | None = None  # (K, 3): slip [m], eps, dpitch [rad]
    vp: np.ndarray | None = None  # (2,) undistorted px
    vp_std: np.ndarray | None = None
    lane_log_h: float | None = None  # ln(height) the lane width gives
    lane_log_h_std: float = math.inf
    chains: tuple[np.ndarray, np.ndarray] | None = None  # (n, K, 2), (n, K)
    chain_noise_px: float = 0.45
    free_pairs: bool = True


@dataclass(slots=True)
class Fit:
    g: np.ndarray
    m: np.ndarray
    cov: np.ndarray  # (NG, NG) of the globals (0 rows for fixed ones)
    cue: dict[str, str] = field(default_factory=dict)
    observable: dict[str, bool] = field(default_factory=dict)
    flow_rms_px: float = float("nan")
    pair_rms_px: np.ndarray | None = None
    point_residual_px: np.ndarray | None = None


class _Layout:
    """Which entries of (globals, per-pair motion) the optimiser moves."""

    def __init__(self, pr: Problem, free_g: np.ndarray):
        self.free_g = np.flatnonzero(free_g)
        self.k = pr.pairs.n_pairs if pr.pairs is not None else 0
        self.n_pair_free = self.k * NP if pr.free_pairs else 0

    @property
    def n(self) -> int:
        return len(self.free_g) + self.n_pair_free

    def split(self, x: np.ndarray, g0: np.ndarray, m0: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        g = g0.copy()
        g[self.free_g] = x[:len(self.free_g)]
        m = x[len(self.free_g):].reshape(self.k, NP) if self.n_pair_free else m0
        return g, m

    def join(self, g: np.ndarray, m: np.ndarray) -> np.ndarray:
        tail = m.ravel() if self.n_pair_free else np.zeros(0)
        return np.concatenate((g[self.free_g], tail))

    def col_g(self, name: str) -> int | None:
        i = G[name]
        hits = np.flatnonzero(self.free_g == i)
        return int(hits[0]) if hits.size else None

    def col_p(self, k: np.ndarray, name: str) -> np.ndarray:
        return len(self.free_g) + np.asarray(k) * NP + P[name]


#: Measurement residuals beyond this many sigmas count less (soft-L1); priors never do.
ROBUST_SCALE_SIGMAS = 2.0


def robust(r: np.ndarray, scale: float = ROBUST_SCALE_SIGMAS) -> np.ndarray:
    """Residuals transformed so that their squares are the soft-L1 cost
    ``2 s^2 (sqrt(1 + r^2 / s^2) - 1)``: quadratic within ``s``, linear beyond (so least
    squares on them is the robust M-estimate, and priors stay quadratic)."""
    return np.sign(r) * scale * np.sqrt(2.0 * (np.sqrt(1.0 + (r / scale) ** 2) - 1.0))


def residual_blocks(pr: Problem, g: np.ndarray, m: np.ndarray) -> dict[str, np.ndarray]:
    """Every block's normalised residuals at (g, m)."""
    f, k1, k2, pitch, yaw, roll, _ = unpack(g)
    out: dict[str, np.ndarray] = {}
    if pr.pairs is not None and len(pr.pairs.pair):
        pred, _ = predict_b(g, m, pr.pairs, pr.c)
        out["flow"] = robust(((pr.pairs.points_b - pred) / pr.flow_noise_px).ravel())
    if pr.gps_d is not None:
        has = np.isfinite(pr.gps_d)
        out["GPS speed"] = (m[has, P["s"]] - pr.gps_d[has]) / pr.gps_d_std[has]
        out["GPS yaw"] = (m[has, P["dpsi"]] - pr.gps_dpsi[has]) / pr.gps_dpsi_std[has]
    if pr.motion_std is not None and pr.pairs is not None:
        out["motion prior"] = (m[:, [P["slip"], P["eps"], P["dpitch"]]] / pr.motion_std).ravel()
    prior = np.isfinite(pr.prior_std) & ~pr.fixed
    out["prior"] = (g[prior] - pr.prior_mean[prior]) / pr.prior_std[prior]
    if pr.vp is not None:
        out["vanishing point"] = (geo.forward_vanishing_point(f, pr.c, pitch, yaw, roll)
                                  - pr.vp) / pr.vp_std
    if pr.lane_log_h is not None:
        out["lane width"] = np.array([(g[G["log_h"]] - pr.lane_log_h) / pr.lane_log_h_std])
    if pr.chains is not None and len(pr.chains[0]):
        out["plumb lines"] = robust((plumb_residuals(pr.chains[0], pr.chains[1], f, pr.c, k1,
                                                     k2) / pr.chain_noise_px)[pr.chains[1]])
    return out


def _sparsity(pr: Problem, lay: _Layout, blocks: dict[str, np.ndarray]
              ) -> tuple[lil_matrix, dict]:
    """The Jacobian's pattern, and each block's row range."""
    # scipy.optimize/sparse cost about 1 s to import; every command imports this stage (the
    # settings tree holds its config), so they load only when a camera is solved for.
    from scipy.sparse import lil_matrix

    spans, r0 = {}, 0
    for name, r in blocks.items():
        spans[name] = (r0, r0 + len(r))
        r0 += len(r)
    sp = lil_matrix((r0, lay.n), dtype=int)
    ng = len(lay.free_g)

    def globals_(a: int, b: int, names: tuple[str, ...]) -> None:
        for nm in names:
            col = lay.col_g(nm)
            if col is not None:
                sp[a:b, col] = 1

    for name, (a, b) in spans.items():
        if name == "flow":
            globals_(a, b, GLOBALS)
            if lay.n_pair_free:
                pair = np.repeat(pr.pairs.pair, 2)
                for j in range(NP):
                    sp[np.arange(a, b), ng + pair * NP + j] = 1
        elif name in ("GPS speed", "GPS yaw") and lay.n_pair_free:
            has = np.flatnonzero(np.isfinite(pr.gps_d))
            sp[np.arange(a, b), lay.col_p(has, "s" if name == "GPS speed" else "dpsi")] = 1
        elif name == "motion prior" and lay.n_pair_free:
            k = np.repeat(np.arange(lay.k), 3)
            which = np.tile([P["slip"], P["eps"], P["dpitch"]], lay.k)
            sp[np.arange(a, b), ng + k * NP + which] = 1
        elif name == "prior":
            prior = np.flatnonzero(np.isfinite(pr.prior_std) & ~pr.fixed)
            for row, i in enumerate(prior):
                col = lay.col_g(GLOBALS[i])
                if col is not None:
                    sp[a + row, col] = 1
        elif name == "vanishing point":
            globals_(a, b, ("log_f", "pitch", "yaw", "roll"))
        elif name == "lane width":
            globals_(a, b, ("log_h",))
        elif name == "plumb lines":
            globals_(a, b, ("log_f", "k1", "k2"))
    return sp, spans


def solve(pr: Problem, g0: np.ndarray, m0: np.ndarray, free_g: np.ndarray,
          max_nfev: int = 60) -> tuple[np.ndarray, np.ndarray, object, dict]:
    """Minimise the robust cost over the free globals (and the pairs' motion)."""
    lay = _Layout(pr, free_g & ~pr.fixed)
    g0 = np.where(pr.fixed, pr.prior_mean, g0)

    def fun(x: np.ndarray) -> np.ndarray:
        g, m = lay.split(x, g0, m0)
        return np.concatenate(list(residual_blocks(pr, g, m).values()))

    sp, spans = _sparsity(pr, lay, residual_blocks(pr, g0, m0))
    lo = np.concatenate((GLOBAL_BOUNDS[0][lay.free_g], np.full(lay.n_pair_free, -np.inf)))
    hi = np.concatenate((GLOBAL_BOUNDS[1][lay.free_g], np.full(lay.n_pair_free, np.inf)))
    x0 = np.clip(lay.join(g0, m0), lo + 1e-9, hi - 1e-9)
    from scipy.optimize import least_squares  # see _sparsity: loaded when a camera is solved

    # scipy's bounded trust-region step fails for a single unknown; dogbox takes it
    res = least_squares(fun, x0, jac_sparsity=sp, method="trf" if lay.n > 1 else "dogbox",
                        bounds=(lo, hi),
                        x_scale="jac", max_nfev=max_nfev)
    g, m = lay.split(res.x, g0, m0)
    return g, m, (res, lay), spans


#: Blocks whose rows are priors, not measurements (the sandwich takes their information as
#: it is; a parameter observable only through ``prior`` is reported as not observable).
PRIOR_BLOCKS = ("prior", "motion prior")


def _clusters(pr: Problem, spans: dict, n_rows: int) -> np.ndarray:
    """Cluster id of every residual row: a pair's flow rows share one, a chain's rows one,
    the vanishing point's two rows one, any other row its own."""
    cid = np.arange(n_rows) + 10_000_000
    if "flow" in spans:
        a, b = spans["flow"]
        cid[a:b] = np.repeat(pr.pairs.pair, 2)
    if "plumb lines" in spans:
        a, b = spans["plumb lines"]
        chain = np.broadcast_to(np.arange(len(pr.chains[1]))[:, None], pr.chains[1].shape)
        cid[a:b] = 1_000_000 + chain[pr.chains[1]]
    if "vanishing point" in spans:
        a, b = spans["vanishing point"]
        cid[a:b] = 5_000_000
    return cid


def _variances(a: np.ndarray, n_g: int) -> np.ndarray:
    """Diagonal of the pseudo-inverse of ``a`` for the first ``n_g`` entries; inf where a
    direction the data leave undetermined involves the parameter."""
    lam, vec = np.linalg.eigh(a)
    tol = 1e-9 * max(float(lam.max()), 1e-30)
    big = lam > tol
    var = (vec[:n_g, big] ** 2 / lam[big]).sum(axis=1)
    null = (vec[:n_g, ~big] ** 2).sum(axis=1)
    return np.where(null > 1e-3, np.inf, var)


def covariance(pr: Problem, g: np.ndarray, m: np.ndarray, res, lay: _Layout, spans: dict,
               useful_std: np.ndarray) -> tuple[np.ndarray, dict[str, str], dict[str, bool]]:
    """Sandwich covariance of the globals, each free global's dominant cue, observability.

    ``useful_std`` (NG,): the one-sigma the data alone (without the ``prior`` rows) must
    reach for a parameter to count as observed in the clip."""
    jac = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    rw = res.fun
    a_all = jac.T @ jac
    cid = _clusters(pr, spans, len(rw))
    is_prior = np.zeros(len(rw), bool)
    for name in PRIOR_BLOCKS:
        if name in spans:
            is_prior[slice(*spans[name])] = True
    score = jac[~is_prior] * rw[~is_prior, None]
    uniq, inv = np.unique(cid[~is_prior], return_inverse=True)
    summed = np.zeros((len(uniq), jac.shape[1]))
    np.add.at(summed, inv, score)
    b = summed.T @ summed + jac[is_prior].T @ jac[is_prior]
    a_inv = np.linalg.pinv(a_all)
    ng = len(lay.free_g)
    sandwich = (a_inv @ b @ a_inv)[:ng, :ng]
    cov = np.zeros((NG, NG))
    cov[np.ix_(lay.free_g, lay.free_g)] = sandwich
    base = _variances(a_all, ng)
    cue, observable = {}, {}
    block_info = {name: jac[slice(*span)].T @ jac[slice(*span)] for name, span in spans.items()}
    for name, info in block_info.items():
        without = _variances(a_all - info, ng)
        if name == "prior":
            for j, gi in enumerate(lay.free_g):
                observable[GLOBALS[gi]] = bool(without[j] <= useful_std[gi] ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = without / base
        for j, gi in enumerate(lay.free_g):
            best = cue.get(GLOBALS[gi])
            if best is None or ratio[j] > best[1]:
                cue[GLOBALS[gi]] = (name, ratio[j])
    return cov, {k: v[0] for k, v in cue.items()}, observable
