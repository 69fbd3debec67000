"""Numerical solution of the averaged Best Fokker-Planck Equation, Eq. `avbfpe` (omega = 0).

    dP/dt = (D/4) d/dOmega [ (1 + (tau Omega)^2)^{-1} dP/dOmega ]

The paper only extracts the identity `idquadr` from this equation; here it is solved
numerically, started from a narrow Gaussian that matches a simulation started at
``Omega_0 = 0``. ``docs/theory.md`` justifies every numerical choice. In short:

* Scaled variables ``x = tau Omega`` and ``s = D tau^2 t = t/t_c`` remove both parameters:
  ``dq/ds = (1/4) d/dx[(1 + x^2)^{-1} dq/dx]``, where ``q(x) = 2 P(Omega)/tau`` is the density
  of ``|x|`` on the half line ``x >= 0`` (``P`` is symmetric, so the flux vanishes at 0).
* Conservative finite volumes on the mapped grid ``x = A sinh(xi)``, ``xi`` uniform: the
  cell size is ``A dxi`` near the origin and ``~ x dxi`` far out, so every width between
  ``A`` (the initial one) and ``x_max`` is resolved by the same number of cells per e-fold:
  the grid follows the growth ``x ~ s^{1/2}`` (early) and ``x ~ s^{1/4}`` (late) without
  regridding. ``x_max`` is set from ``t_max`` so that the law is below ``exp(-tail_exponent)``
  there.
* The face conductance is chosen so that the discrete identity is exact:
  ``k_f = x_f / (4 [g(x_{i+1}) - g(x_i)])`` with ``g(x) = x^4/4 + x^2/2`` -- a second-order
  approximation of ``(1 + x_f^2)^{-1} / (4 (x_{i+1} - x_i))`` -- gives, by summation by parts,
  ``d/ds sum_i g(x_i) q_i h_i = (1/4) sum_i q_i h_i - q_N x_max/4`` exactly.
* The unknowns are the face values of the tail mass ``R_f = sum_{i >= f} q_i h_i`` (the
  flux form of the finite-volume scheme: ``dR_f/ds`` is the flux through face ``f``), with
  ``R_0 = 1`` and ``R_N = 0`` (zero flux at both ends): the mass is exactly 1 by construction
  and moments ``sum_i x_i^k (R_i - R_{i+1})`` keep full relative precision in the tail.
* Time stepping: the two-stage, L-stable, stiffly accurate SDIRK2 of Alexander
  (``gamma = 1 - 1/sqrt 2``), second order, each stage a tridiagonal solve with
  :func:`scipy.linalg.solve_banded`; the operator is never applied explicitly (stage
  derivatives are recovered as ``(Y - y)/(gamma ds)``), so the very stiff fine cells near the
  origin do not amplify round-off. Steps are log-spaced,
  ``s_{n+1}/s_n <= 10^{1/steps_per_decade}``, and land exactly on the output times.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import solve_banded
from scipy.special import erfc

from stochpend.text._docs import documented
from stochpend.theory.laws import (
    BFPE_LONGTIME_MEAN_PREFACTOR,
    PHI_INF,
    _check_D,
    _check_tau,
    _fail,
    _scalar,
)

__all__ = ["BFPEGrid", "solve_bfpe"]

_GAMMA = 1.0 - 1.0 / math.sqrt(2.0)  # SDIRK2 (Alexander 1977) diagonal coefficient


def _g(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Identity weight ``g(x) = x^4/4 + x^2/2``: ``tau^2 [(tau^2/4) Omega^4 + Omega^2/2]``."""
    x2 = x * x
    return 0.25 * x2 * x2 + 0.5 * x2


class BFPEGrid:
    """Finite-volume grid on ``x = tau Omega >= 0`` with the mapping ``x = A sinh(xi)``.

    Faces ``x_f = A sinh(f dxi)``, ``f = 0..N`` (``x_0 = 0``, ``x_N = x_max``); cell ``i``
    lies between faces ``i`` and ``i + 1``, has width ``h_i`` and centre
    ``x_i = (x_f[i] + x_f[i+1])/2``.

    Parameters
    ----------
    n_cells : int
        Number of cells ``N`` on the half line.
    x_inner : float
        ``A``: below it the grid is nearly uniform (spacing ``A dxi``), above it geometric.
    x_max : float
        Outer (zero-flux) wall.
    """

    def __init__(self, n_cells: int, x_inner: float, x_max: float) -> None:
        self.n_cells = int(n_cells)
        self.x_inner = float(x_inner)
        self.x_max = float(x_max)
        self.dxi = math.asinh(x_max / x_inner) / n_cells
        faces = x_inner * np.sinh(np.arange(n_cells + 1, dtype=np.float64) * self.dxi)
        faces[0] = 0.0
        faces[-1] = x_max
        self.faces = faces
        self.centres = 0.5 * (faces[:-1] + faces[1:])
        self.widths = np.diff(faces)
        c = self.centres
        a, b = c[:-1], c[1:]
        # g(b) - g(a), factored to avoid cancellation: (b - a)(b + a)[1/2 + (a^2 + b^2)/4]
        dg = (b - a) * (b + a) * (0.5 + 0.25 * (a * a + b * b))
        #: Conductance of the interior faces 1..N-1: flux F_f = -k_f (q_f - q_{f-1}).
        self.conductance = faces[1:-1] / (4.0 * dg)
        #: ``g`` at the cell centres.
        self.g = _g(c)
        # dR_f/ds = k_f [(R_{f+1} - R_f)/h_f - (R_f - R_{f-1})/h_{f-1}] for f = 1..N-1
        self._upper = self.conductance / self.widths[1:]
        self._lower = self.conductance / self.widths[:-1]

    def tail_mass(self, cdf_complement: NDArray[np.float64]) -> NDArray[np.float64]:
        """Interior unknowns ``R_1..R_{N-1}`` from values of ``P(|x| > x_f)`` at the faces."""
        return np.asarray(cdf_complement, dtype=np.float64)[1:-1]

    def cell_masses(self, R: NDArray[np.float64]) -> NDArray[np.float64]:
        """Masses ``q_i h_i = R_i - R_{i+1}`` of the cells (``R_0 = 1``, ``R_N = 0``)."""
        full = np.concatenate(([1.0], R, [0.0]))
        return full[:-1] - full[1:]

    def density(self, R: NDArray[np.float64]) -> NDArray[np.float64]:
        """Cell averages ``q_i`` of the density of ``|x|``."""
        return self.cell_masses(R) / self.widths

    def banded(self, c_ds: float) -> NDArray[np.float64]:
        """``I - c_ds A`` in the banded layout of :func:`scipy.linalg.solve_banded`."""
        n = self.n_cells - 1
        ab = np.zeros((3, n))
        ab[0, 1:] = -c_ds * self._upper[:-1]
        ab[1] = 1.0 + c_ds * (self._upper + self._lower)
        ab[2, :-1] = -c_ds * self._lower[1:]
        return ab

    def source(self, c_ds: float) -> NDArray[np.float64]:
        """``c_ds b``: the contribution of the fixed ``R_0 = 1`` to face 1."""
        b = np.zeros(self.n_cells - 1)
        b[0] = c_ds * self._lower[0]
        return b


def _sdirk2_step(grid: BFPEGrid, R: NDArray[np.float64], ds: float) -> NDArray[np.float64]:
    """One step of Alexander's L-stable SDIRK2 for ``dR/ds = A R + b``.

    ``Y1 = R + gamma ds k1``, ``R_new = R + (1 - gamma) ds k1 + gamma ds k2`` with
    ``k_j = A Y_j + b``; ``k1`` is recovered as ``(Y1 - R)/(gamma ds)``, never by applying ``A``.
    Both stages solve with the same matrix ``I - gamma ds A``.
    """
    c = _GAMMA * ds
    ab = grid.banded(c)
    src = grid.source(c)
    Y1 = solve_banded((1, 1), ab, R + src, check_finite=False)
    return solve_banded((1, 1), ab, R + ((1.0 - _GAMMA) / _GAMMA) * (Y1 - R) + src, check_finite=False)


def _step_nodes(s_start: float, s_targets: NDArray[np.float64], ratio: float) -> list[NDArray[np.float64]]:
    """Geometric sub-steps from ``s_start`` to each target (ratio of consecutive nodes <= ``ratio``)."""
    out = []
    a = s_start
    for b in s_targets:
        n = max(1, math.ceil(math.log(b / a) / math.log(ratio) - 1e-9))
        nodes = a * (b / a) ** (np.arange(1, n + 1) / n)
        nodes[-1] = b
        out.append(nodes)
        a = b
    return out


#: Largest grids accepted: beyond them the arrays (the step nodes are stored per decade) or
#: the time would be absurd (an out-of-memory traceback, or a run that does not end).
MAX_N_CELLS = 10_000_000
#: Largest solve accepted without ``max_cell_steps``: ~1.4 h at the measured rate.
DEFAULT_MAX_CELL_STEPS = 1e11
#: Cell-steps per second of the solve, measured on the 2-core development machine (1e6 cells,
#: t_max = 10: 7.4e8 cell-steps in 35 s). Only for the estimate in a refusal.
CELL_STEPS_PER_S = 2e7
#: Floats per cell held at once besides the stored laws (grid, state, the banded solve).
_WORK_FLOATS_PER_CELL = 24
MAX_STEPS_PER_DECADE = 100_000
MAX_N_TIMES = 1_000_000
MAX_N_OMEGA = 1_000_000
#: Range of tau: the moments of E are computed as moments of x = tau Omega over tau**8.
MIN_TAU = 1e-20
MAX_TAU = 1e20
#: Range of the scaled times t/t_c = t D tau**2 the solver represents without overflow.
MIN_SCALED_TIME = 1e-30
MAX_SCALED_TIME = 1e30
#: Range of the rate 1/t_c = D tau**2.
MIN_RATE = 1e-250
MAX_RATE = 1e250


def _integer(name: str, value: Any, accepted: str, minimum: int, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            _fail(name, value, accepted)
    v = int(value)
    if v < minimum or (maximum is not None and v > maximum):
        _fail(name, value, accepted)
    return v


def cell_steps_per_s() -> float:
    """The solve's expected rate now: measured by earlier solves on this machine and scaled to the
    load (:mod:`stochpend.numerics._calibration`), else :data:`CELL_STEPS_PER_S`. One thread."""
    from stochpend.numerics import _calibration

    return _calibration.rate("bfpe", CELL_STEPS_PER_S, 1)[0]


def _check_cost(n_cells: int, n_times: int, n_steps: int, max_cell_steps: float | None) -> tuple[float, float, float]:
    """Refuse, before any work, a solve that cannot fit in memory or would not end; else return
    ``(cell-steps, expected seconds, bytes of the stored laws and work arrays)``."""
    from stochpend.runs import resources

    accepted = "max_cell_steps must be a number > 0 (inf: no limit)"
    try:
        limit = DEFAULT_MAX_CELL_STEPS if max_cell_steps is None else float(max_cell_steps)
    except (TypeError, ValueError):
        _fail("max_cell_steps", max_cell_steps, accepted)
    if isinstance(max_cell_steps, bool) or not limit > 0:  # NaN too
        _fail("max_cell_steps", max_cell_steps, accepted)
    need = float(n_cells) * (n_times + _WORK_FLOATS_PER_CELL) * 8
    have = resources.available_memory()
    if have is not None and need > have:
        name = "n_times" if n_times > _WORK_FLOATS_PER_CELL else "n_cells"
        raise ValueError(f"{name}={n_times if name == 'n_times' else n_cells} is not accepted: the solve keeps "
                         f"n_times x n_cells = {n_times} x {n_cells} laws, {resources.format_bytes(need)} in all, "
                         f"more than the {resources.format_bytes(have)} available; use fewer cells or output times")
    work = float(n_cells) * n_steps
    seconds = work / cell_steps_per_s()
    if work > limit:
        raise ValueError(f"n_cells={n_cells} is not accepted: the solve needs about {work:.3g} cell-steps "
                         f"(n_cells x time steps = {n_cells} x {n_steps}), roughly "
                         f"{resources.format_seconds(seconds)}, above the limit of {limit:.3g}; "
                         "use fewer cells or steps per decade, or raise the limit with max_cell_steps= "
                         "(--max-cell-steps)")
    return work, seconds, need


@documented  # help() shows the signature's defaults and the paper's equation numbers
def solve_bfpe(
    *,
    D: float,
    tau: float,
    t_max: float,
    times: ArrayLike | None = None,
    n_times: int = 40,
    t0: float | None = None,
    omega: float = 0.0,
    n_cells: int = 1000,
    steps_per_decade: int = 100,
    tail_exponent: float = 200.0,
    n_Omega: int = 201,
    u_max: float = 5.0,
    max_cell_steps: float | None = None,
    log: Callable[[str], None] | None = None,
) -> xr.Dataset:
    """Solve the averaged B.F.P.E., Eq. `avbfpe`, for a start at ``Omega_0 = 0`` (omega = 0).

    Parameters
    ----------
    D : float
        OU noise amplitude, > 0.
    tau : float
        OU correlation time, > 0. ``t_c = 1/(D tau^2)`` (Eq. `tpcross`).
    t_max : float
        Last time, > 0.
    times : array_like, optional
        Output times, strictly increasing, in ``(t0, t_max]``. Default: ``n_times`` log-spaced
        times from ``1e-3 t_max`` to ``t_max`` (the simulator's default grid).
    n_times : int, optional
        Number of default output times (ignored when ``times`` is given).
    t0 : float, optional
        Start time. The initial law is the exact short-time Gaussian ``P_{t0}(Omega) =
        (pi D t0)^{-1/2} exp(-Omega^2/(D t0))`` (variance ``D t0/2``, Eq. `eq:pdfOmegablanc`),
        i.e. the law at ``t0`` of a start at ``Omega = 0`` up to a relative error
        ``O(t0/t_c)``. Default: ``min(1e-6 t_c, 1e-3 times[0])``.
    omega : float, optional
        Must be 0: the averaged B.F.P.E. is derived for ``omega = 0``.
    n_cells : int, optional
        Cells on the half line ``Omega >= 0`` (halving it changes ``mean_E`` at
        ``10^4 t_c`` by about 1e-4 relative).
    steps_per_decade : int, optional
        Time steps per decade of ``t`` (log-spaced from ``t0``).
    tail_exponent : float, optional
        The outer wall is placed where bounds of the law fall below ``exp(-tail_exponent)``
        at ``t_max``; the ``boundary_flux`` output checks it a posteriori.
    n_Omega : int, optional
        Points of the output law ``P_Omega`` (symmetric about 0).
    u_max : float, optional
        The output law is sampled on ``Omega = u <Omega^2>^{1/2}``, ``u in [-u_max, u_max]``.
    max_cell_steps : float, optional
        Refuse, before any work, a solve needing more than this many cell-steps (``n_cells`` x
        time steps; default :data:`DEFAULT_MAX_CELL_STEPS`, ``math.inf``: no limit). A solve
        whose laws at the output times (``n_times x n_cells`` floats) do not fit in memory is
        refused too.
    log : callable, optional
        Receives one line, ``"estimate: ..."`` (the work, the expected duration at the rate
        measured on this machine, the memory), before a solve expected to last longer than
        :data:`stochpend.runs.resources.LONG_RUN_S`.

    Returns
    -------
    xarray.Dataset
        Coordinate ``time``; variables ``mean_E``, ``mean_E2``, ``mean_E3``, ``mean_E4``
        (``E = Omega^2/2``), ``skewness`` (``<E^3>/<E^2>^{3/2}``), ``flatness``
        (``<E^4>/<E^2>^2``), ``mean_Omega2``, ``mean_Omega4``, ``phi``
        (``<Omega^4>/<Omega^2>^2``, Eq. `deflatness`), ``mass``, ``identity_residual``
        (relative residual of Eq. `idquadr`), ``identity_lhs``, ``boundary_flux``, and the law
        ``P_Omega(time, u)`` with the 2-D coordinate ``Omega(time, u) = u
        <Omega^2>^{1/2}(time)``; attributes hold all parameters and numerical settings.

    Raises
    ------
    ValueError
        One line naming the parameter, its value and what is accepted.
    """
    D = _check_D(D, positive=True)
    tau = _check_tau(tau)
    if not MIN_TAU <= tau <= MAX_TAU:
        _fail("tau", tau, f"tau must be a finite number in [{MIN_TAU:g}, {MAX_TAU:g}] here (the moments of E "
              "scale as tau**-8)")
    om = _scalar("omega", omega, "omega must be 0: the averaged B.F.P.E. (avbfpe) is derived for omega = 0")
    if om != 0.0:
        _fail("omega", omega, "omega must be 0: the averaged B.F.P.E. (avbfpe) is derived for omega = 0")
    t_max = _scalar("t_max", t_max, "t_max must be a finite number > 0")
    if t_max <= 0:
        _fail("t_max", t_max, "t_max must be a finite number > 0")
    n_cells = _integer("n_cells", n_cells, f"n_cells must be an integer in [20, {MAX_N_CELLS}]", 20, MAX_N_CELLS)
    steps_per_decade = _integer(
        "steps_per_decade", steps_per_decade,
        f"steps_per_decade must be an integer in [2, {MAX_STEPS_PER_DECADE}]", 2, MAX_STEPS_PER_DECADE,
    )
    tail_exponent = _scalar("tail_exponent", tail_exponent, "tail_exponent must be a finite number >= 10")
    if tail_exponent < 10:
        _fail("tail_exponent", tail_exponent, "tail_exponent must be a finite number >= 10")
    n_Omega = _integer("n_Omega", n_Omega, f"n_Omega must be an integer in [3, {MAX_N_OMEGA}]", 3, MAX_N_OMEGA)
    u_max = _scalar("u_max", u_max, "u_max must be a finite number > 0")
    if u_max <= 0:
        _fail("u_max", u_max, "u_max must be a finite number > 0")

    if times is None:
        n_times = _integer("n_times", n_times, f"n_times must be an integer in [1, {MAX_N_TIMES}]", 1, MAX_N_TIMES)
        grid_t = np.geomspace(t_max * 1e-3, t_max, n_times) if n_times > 1 else np.array([t_max])
        grid_t[-1] = t_max
    else:
        try:
            grid_t = np.asarray(times, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            _fail("times", times, "times must be a list of numbers in (0, t_max]")
        if grid_t.size == 0 or not np.all(np.isfinite(grid_t)):
            _fail("times", times, "times must be a non-empty list of finite numbers in (0, t_max]")
        if np.any(grid_t <= 0) or np.any(grid_t > t_max):
            _fail("times", times, f"times must lie in (0, t_max] = (0, {t_max}]")
        if np.any(np.diff(grid_t) <= 0):
            _fail("times", times, "times must be strictly increasing")

    # The problem is solved in s = t/t_c = t D tau**2, and <E**4> is computed as <x**8>/tau**8
    # (x = tau Omega, x**2 ~ s): these ranges keep every moment within the floats.
    rate = D * tau * tau  # 1/t_c (a product: never an OverflowError, at worst inf or 0)
    if not MIN_RATE <= rate <= MAX_RATE:
        _fail("D", D, f"with tau={tau:g}, 1/t_c = D tau**2 (here {rate:.3g}) must lie in [{MIN_RATE:g}, {MAX_RATE:g}]")
    s_max = t_max * rate
    if not (MIN_SCALED_TIME <= s_max <= MAX_SCALED_TIME and MIN_SCALED_TIME <= grid_t[0] * rate):
        _fail("t_max", t_max, f"with D={D:g} and tau={tau:g}, the output times in units of t_c = 1/(D tau**2), "
              f"t*D*tau**2 (here {float(grid_t[0]) * rate:.3g} to {s_max:.3g}), must lie in "
              f"[{MIN_SCALED_TIME:g}, {MAX_SCALED_TIME:g}]")
    t_c = 1.0 / (D * tau**2)
    if t0 is None:
        t0 = min(1e-6 * t_c, 1e-3 * float(grid_t[0]))
    else:
        t0 = _scalar("t0", t0, f"t0 must be a finite number in (0, times[0]) = (0, {grid_t[0]})")
        if not 0 < t0 < grid_t[0]:
            _fail("t0", t0, f"t0 must be a finite number in (0, times[0]) = (0, {grid_t[0]})")

    # ---- scaled problem: x = tau Omega, s = t/t_c -------------------------------------------
    s0 = t0 / t_c
    s_out = grid_t / t_c
    s_max = t_max / t_c
    sigma0 = math.sqrt(s0 / 2.0)  # initial std of x
    n_steps_expected = math.ceil(steps_per_decade * math.log10(s_max / s0)) + grid_t.size
    work, seconds, need = _check_cost(n_cells, grid_t.size, n_steps_expected, max_cell_steps)
    from stochpend.numerics import _calibration
    from stochpend.runs import resources

    if log is not None and seconds > resources.LONG_RUN_S:
        log(f"estimate: about {work:.3g} cell-steps (n_cells x time steps = {n_cells} x {n_steps_expected}), "
            f"roughly {resources.format_seconds(seconds)} on one CPU core at ~{work / seconds:.2g} cell-steps/s; "
            f"memory {resources.format_bytes(need)}")
    load = _calibration.current_load()  # the rate is stored as on an idle machine (later estimates)
    started = time.perf_counter()
    # Far tail (heuristic bound, checked a posteriori by `boundary_flux`): the diffusion
    # coefficient (1 + x^2)^-1 is below both 1 (white law, exp(-x^2/s)) and x^-2 (similarity
    # law, exp(-x^4/(4 s))). Put the wall beyond where the smaller bound is exp(-tail_exponent).
    x_gauss = math.sqrt(tail_exponent * s_max)
    x_quart = (4.0 * tail_exponent * s_max) ** 0.25
    x_max = max(min(x_gauss, x_quart) * 1.25, 40.0 * sigma0)
    grid = BFPEGrid(n_cells, sigma0, x_max)

    x = grid.centres
    # Exact initial cell masses of the Gaussian of variance s0/2: P(|x| > x_f) = erfc(x_f/sqrt(s0)).
    R = grid.tail_mass(erfc(grid.faces / math.sqrt(s0)))

    def diagnostics(R: NDArray[np.float64]) -> dict[str, float]:
        w = grid.cell_masses(R)
        return {
            "mass": float(np.sum(w)),
            "m2": float(np.sum(x**2 * w)),
            "m4": float(np.sum(x**4 * w)),
            "m6": float(np.sum(x**6 * w)),
            "m8": float(np.sum(x**8 * w)),
            "M": float(np.sum(grid.g * w)),
        }

    def edge(R: NDArray[np.float64]) -> float:
        # defect rate of the discrete identity: q_N x_max / 4 (q_N = R_{N-1}/h_{N-1})
        return float(R[-1] / grid.widths[-1] * grid.x_max / 4.0)

    start = diagnostics(R)
    ratio = 10.0 ** (1.0 / steps_per_decade)
    records: list[dict[str, float]] = []
    laws: list[NDArray[np.float64]] = []
    boundary_term = 0.0  # integral of q_N x_max/4 ds: the exact defect of the identity
    s = s0
    n_steps = 0
    for nodes in _step_nodes(s0, s_out, ratio):
        for s_next in nodes:
            edge_before = edge(R)
            R = _sdirk2_step(grid, R, s_next - s)
            boundary_term += 0.5 * (edge_before + edge(R)) * (s_next - s)
            s = s_next
            n_steps += 1
        d = diagnostics(R)
        d["boundary_term"] = boundary_term
        records.append(d)
        laws.append(grid.density(R))

    _calibration.record_rate("bfpe", work, time.perf_counter() - started, 1, load=load)
    mass = np.array([r["mass"] for r in records])
    m2 = np.array([r["m2"] for r in records])
    m4 = np.array([r["m4"] for r in records])
    m6 = np.array([r["m6"] for r in records])
    m8 = np.array([r["m8"] for r in records])
    Mx = np.array([r["M"] for r in records])
    growth = (s_out - s0) / 4.0
    identity_residual = (Mx - start["M"] - growth) / growth

    mean_Omega2 = m2 / tau**2
    mean_Omega4 = m4 / tau**4
    mean_E = mean_Omega2 / 2.0
    mean_E2 = mean_Omega4 / 4.0
    mean_E3 = m6 / tau**6 / 8.0
    mean_E4 = m8 / tau**8 / 16.0

    u = np.linspace(-u_max, u_max, n_Omega)
    u = 0.5 * (u - u[::-1])  # exactly symmetric
    sig_x = np.sqrt(m2)
    P = np.empty((grid_t.size, n_Omega))
    for i, qi in enumerate(laws):
        xs = np.abs(u) * sig_x[i]
        P[i] = 0.5 * tau * np.interp(xs, x, qi, left=qi[0], right=0.0)

    time_attrs = {"long_name": "time t", "units": "paper time units"}
    ds = xr.Dataset(
        data_vars={
            "mean_E": ("time", mean_E, {"long_name": "<E> = <Omega^2>/2 (omega = 0)"}),
            "mean_E2": ("time", mean_E2, {"long_name": "<E^2> = <Omega^4>/4"}),
            "mean_E3": ("time", mean_E3, {"long_name": "<E^3> = <Omega^6>/8"}),
            "mean_E4": ("time", mean_E4, {"long_name": "<E^4> = <Omega^8>/16"}),
            "skewness": (
                "time",
                mean_E3 / mean_E2**1.5,
                {"long_name": "S = <E^3>/<E^2>^(3/2) (raw moments)"},
            ),
            "flatness": ("time", mean_E4 / mean_E2**2, {"long_name": "F = <E^4>/<E^2>^2 (raw moments)"}),
            "mean_Omega2": ("time", mean_Omega2, {"long_name": "<Omega^2>"}),
            "mean_Omega4": ("time", mean_Omega4, {"long_name": "<Omega^4>"}),
            "phi": ("time", m4 / m2**2, {"long_name": "phi = <Omega^4>/<Omega^2>^2 (deflatness)"}),
            "mass": ("time", mass, {"long_name": "integral of P_t(Omega) dOmega"}),
            "identity_lhs": (
                "time",
                Mx / tau**2,
                {"long_name": "(tau^2/4)<Omega^4> + (1/2)<Omega^2> (idquadr, left side)"},
            ),
            "identity_residual": (
                "time",
                identity_residual,
                {
                    "long_name": "relative residual of idquadr: "
                    "[lhs(t) - lhs(t0) - D (t - t0)/4] / [D (t - t0)/4]",
                },
            ),
            "boundary_flux": (
                "time",
                np.array([r["boundary_term"] for r in records]) / growth,
                {
                    "long_name": "identity defect due to the outer wall, relative "
                    "(int q_N x_max/4 ds / growth)"
                },
            ),
            "P_Omega": (
                ("time", "u"),
                P,
                {"long_name": "P_t(Omega) at Omega(time, u)", "units": "1/Omega"},
            ),
        },
        coords={
            "time": ("time", grid_t, time_attrs),
            "u": ("u", u, {"long_name": "Omega / <Omega^2>^(1/2)"}),
            "Omega": (
                ("time", "u"),
                u[None, :] * np.sqrt(mean_Omega2)[:, None],
                {"long_name": "Omega = u <Omega^2>^(1/2)"},
            ),
        },
        attrs={
            "equation": "avbfpe: dP/dt = (D/4) d/dOmega[(1 + (tau Omega)^2)^-1 dP/dOmega], omega = 0",
            "D": D,
            "tau": tau,
            "omega": 0.0,
            "t_max": t_max,
            "t0": t0,
            "t_c": t_c,
            "initial_law": "Gaussian of variance D t0/2 (eq:pdfOmegablanc at t0): start at Omega = 0",
            "scheme": "finite volumes in x = tau Omega >= 0 on x = A sinh(xi), unknowns = tail masses "
            "at the faces; identity-exact face conductance x_f/(4 [g(x_i+1) - g(x_i)]), "
            "g = x^4/4 + x^2/2; L-stable SDIRK2 on log-spaced steps in s = t/t_c",
            "n_cells": n_cells,
            "steps_per_decade": steps_per_decade,
            "n_steps": n_steps,
            "x_inner": grid.x_inner,
            "x_max": grid.x_max,
            "Omega_max": grid.x_max / tau,
            "dxi": grid.dxi,
            "tail_exponent": tail_exponent,
            "mass_error_max": float(np.max(np.abs(mass - 1.0))),
            "identity_residual_max": float(np.max(np.abs(identity_residual))),
            "longtime_mean_prefactor": BFPE_LONGTIME_MEAN_PREFACTOR,
            "longtime_phi": PHI_INF,
        },
    )
    return ds
