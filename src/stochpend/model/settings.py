"""Validated, immutable simulation settings.

Every check happens here, once, at the Python boundary; kernels trust what they receive.
Each refusal is a ``ValueError`` with one line that names the parameter, the value received
and what is accepted; the command line prints that line and exits with code 2.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from types import SimpleNamespace
from typing import Any, NoReturn

import numpy as np

from stochpend.model import dynamics as _dynamics
from stochpend.model import noises as _noises
from stochpend.model import observables as _observables
from stochpend.model import oscillators as _oscillators
from stochpend.model import parameters as _parameters
from stochpend.numerics import _hostmath
from stochpend.numerics import rng as _rng

#: The built-in noises (a registered noise is accepted too: ``stochpend.noises.register``).
NOISES = tuple(noise.name for noise in _noises.BUILTIN)
#: Built-in noises with a correlation time tau.
COLORED_NOISES = tuple(noise.name for noise in _noises.BUILTIN if noise.colored)
BACKENDS = ("cpu", "auto", "cuda")

#: Default step controls, from the accuracy study in docs/numerics.md.
DEFAULT_H_MAX = 0.05
DEFAULT_STEP_C = 0.1
DEFAULT_HIST_BINS = 100
DEFAULT_N_BATCHES = 100
#: Largest accepted sizes. paths: the global path index is a 64-bit counter of the random
#: streams. n_times: the default grid is allocated while validating (the memory of larger
#: outputs is checked by stochpend.runs.resources). power_n: beyond it x**(2n) overflows for any
#: |x| > 1.42, a hard wall rather than an oscillator. omega: omega**2 must stay finite.
MAX_PATHS = 2**63 - 1
MAX_N_TIMES = 1_000_000
MAX_POWER_N = 1000
MAX_OMEGA = 1e150
#: Range of t_max: the default output grid, log-spaced from t_max/1000, must be representable.
MIN_T_MAX = 1e-300
MAX_T_MAX = 1e300


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)`` on one line, shortened to about ``limit`` characters (error messages)."""
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the refusal
        text = f"<{type(value).__name__}>"
    text = " ".join(text.split())
    if len(text) > limit:
        text = text[: limit - 5] + " ...)" if text.endswith(")") else text[: limit - 4] + " ..."
    return text


def _fail(name: str, value: Any, accepted: str) -> NoReturn:
    raise ValueError(f"{name}={short_repr(value)} is not accepted: {accepted}")


def _finite(name: str, value: Any, accepted: str) -> float:
    if isinstance(value, (complex, np.complexfloating)):
        _fail(name, value, accepted)
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        _fail(name, value, accepted)
    if not math.isfinite(v):
        _fail(name, value, accepted)
    return v


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


def _float_array(value: Any) -> np.ndarray:
    """``np.asarray(value, float64)``, refusing complex numbers (TypeError) instead of
    dropping their imaginary part."""
    raw = np.asarray(value)
    if raw.dtype.kind == "c":
        raise TypeError("complex numbers are not accepted")
    return raw.astype(np.float64)


@dataclass(frozen=True)
class SimulationConfig:
    """Everything that determines a simulation's numbers (all times in the paper's units).

    Construct with :meth:`build`, which validates and fills the defaults.
    """

    noise: str
    D: float
    tau: float | None
    omega: float
    paths: int
    t_max: float
    times: tuple[float, ...]
    seed: int
    theta0: float | None  # None: uniform on [-pi, pi)
    Omega0: float
    xi0: float | None  # None: stationary OU law N(0, D/(2 tau))
    h_max: float
    step_c: float
    hist_bins: int
    hist_E_max: tuple[float, ...]
    n_batches: int
    potential: str = "pendulum"
    power_n: int = 2
    coupling: str = "force"
    omega_noise: float | None = None  # harmonic noise: its oscillator's frequency W
    #: Names of registered user observables whose means the run reports (stochpend.observables).
    observables: tuple[str, ...] = ()
    #: The noise's own parameters (stochpend.model.parameters), sorted (name, value) pairs.
    noise_params: tuple[tuple[str, float], ...] = ()
    #: The oscillator's own parameters (a model's ``parameters``), sorted (name, value) pairs.
    osc_params: tuple[tuple[str, float], ...] = ()
    #: The family's terms that differ from their defaults (stochpend.model.dynamics: damping, torque,
    #: drives, additive noise), sorted (name, value) pairs; empty for the paper's model.
    dyn_params: tuple[tuple[str, float], ...] = ()
    #: The joint (x, Omega) histogram (:func:`joint_grid`): (nx, nOmega) bins, empty: none.
    joint_bins: tuple[int, ...] = ()
    #: Its x range (lo, hi), a non-periodic oscillator's only; empty: the default.
    joint_x_range: tuple[float, ...] = ()
    #: Its Omega range [-max, max], one per output time; empty when there is no histogram.
    joint_Omega_max: tuple[float, ...] = ()
    #: The additive noise xi_a's noise, a registered noise's name (stochpend.model.dynamics); None:
    #: white when additive_tau = 0, Ornstein-Uhlenbeck when > 0 (as before the setting).
    additive_noise: str | None = None
    extra: dict = field(default_factory=dict)

    # -- derived, cheap -------------------------------------------------------------------
    @property
    def batch_size(self) -> int:
        return -(-self.paths // self.n_batches)

    @property
    def tau_or_zero(self) -> float:
        return 0.0 if self.tau is None else self.tau

    @property
    def omega_noise_or_zero(self) -> float:
        return 0.0 if self.omega_noise is None else self.omega_noise

    def to_attrs(self) -> dict[str, Any]:
        """Flat attributes for NetCDF (None becomes the string "none" or "uniform")."""
        d = asdict(self)
        d.pop("extra")
        d.pop("times")
        d.pop("hist_E_max")
        for name in ("joint_bins", "joint_x_range", "joint_Omega_max"):
            d.pop(name)
        if self.joint_bins:  # the grid itself is in the Dataset's edge variables
            d["joint_bins"] = ",".join(str(b) for b in self.joint_bins)
        d["tau"] = "none" if self.tau is None else self.tau
        d["theta0"] = "uniform" if self.theta0 is None else self.theta0
        d["xi0"] = "stationary" if self.xi0 is None else self.xi0
        d["omega_noise"] = "none" if self.omega_noise is None else self.omega_noise
        if self.observables:
            d["observables"] = ", ".join(self.observables)
        else:
            d.pop("observables")
        d.pop("noise_params", None)
        if self.noise_params:  # the noise's own parameters: one line, and each exactly
            d["noise_parameters"] = _parameters.describe(self.noise_params)
            d.update({f"noise_{name}": value for name, value in self.noise_params})
        d.pop("osc_params", None)
        if self.osc_params:  # the oscillator's own parameters, likewise
            d["potential_parameters"] = _parameters.describe(self.osc_params)
            d.update({f"potential_{name}": value for name, value in self.osc_params})
        d.pop("dyn_params", None)
        if self.dyn_params:  # the family's terms that are on (stochpend.model.dynamics)
            d["dynamics_parameters"] = _parameters.describe(self.dyn_params)
            d.update(dict(self.dyn_params))
        if self.additive_noise is None:  # unset: the attributes are what they were
            d.pop("additive_noise")
        return d

    @property
    def keys(self) -> _rng.RunKeys:
        """The run's Philox keys (:func:`stochpend.numerics.rng.run_keys`): the one place its seed
        becomes a key."""
        return _rng.run_keys(self.seed)

    @classmethod
    def build(
        cls,
        *,
        noise: str = "ou",
        D: float = 1.0,
        tau: float | None = 1.0,
        omega: float = 1.0,
        paths: int = 10_000,
        t_max: float = 1000.0,
        times: Any = None,
        n_times: int = 40,
        seed: int = 0,
        theta0: float | str | None = "uniform",
        Omega0: float = 0.0,
        xi0: float | str | None = "stationary",
        h_max: float = DEFAULT_H_MAX,
        step_c: float = DEFAULT_STEP_C,
        hist_bins: int = DEFAULT_HIST_BINS,
        hist_E_max: Any = None,
        n_batches: int = DEFAULT_N_BATCHES,
        potential: str = "pendulum",
        power_n: int = 2,
        coupling: str = "force",
        omega_noise: float | None = None,
        observables: Any = (),
        noise_params: Any = None,
        osc_params: Any = None,
        dyn_params: Any = None,
        joint_bins: Any = None,
        joint_x_range: Any = None,
        joint_Omega_max: Any = None,
        additive_noise: str | None = None,
    ) -> SimulationConfig:
        """Validate every argument and return the frozen configuration. ``noise_params``: the
        values of the parameters the noise declares for itself (:mod:`stochpend.model.parameters`),
        a mapping or (name, value) pairs; the noise's defaults fill the others. It may also hold
        the oscillator's own parameters (one keyword space, as ``simulate(**kwargs)``, ``--param``
        and sweep keys give them; :func:`stochpend.model.parameters.split` routes each name to the
        piece that declares it, refusing a name both declare). ``osc_params``: the oscillator's,
        given apart (a checkpoint's JSON); stored in ``osc_params``, the oscillator's defaults
        filling the others. ``additive_noise``: the additive noise's noise, a registered noise's
        name (:mod:`stochpend.model.dynamics`; None: white or OU by ``additive_tau``); its own
        parameters come as ``additive_<name>`` among the family's."""
        observables = _observables.resolve(observables)
        channel = _additive_noise(additive_noise)
        noise_piece, D, tau, omega_noise = _checked_noise(noise, D, tau, omega_noise)
        omega_accepted = f"omega must be a finite number in [0, {MAX_OMEGA:g}] (the pendulum frequency)"
        omega = _finite("omega", omega, omega_accepted)
        if omega < 0 or omega > MAX_OMEGA:
            _fail("omega", omega, omega_accepted)
        paths = _integer("paths", paths, "paths must be an integer in [1, 2**63)", 1, MAX_PATHS)
        t_max_accepted = f"t_max must be a finite number in [{MIN_T_MAX:g}, {MAX_T_MAX:g}]"
        t_max = _finite("t_max", t_max, t_max_accepted)
        if not MIN_T_MAX <= t_max <= MAX_T_MAX:
            _fail("t_max", t_max, t_max_accepted)
        seed = _integer("seed", seed, "seed must be an integer in [0, 2**64)", 0)
        if seed >= 2**64:
            _fail("seed", seed, "seed must be an integer in [0, 2**64)")

        grid = _output_grid(times, n_times, t_max)

        theta0_v, Omega0, xi0_v = _initial_values(theta0, Omega0, xi0, noise_piece)

        oscillator, power_n, q, noise_params_v, osc_params_v, dyn_params_v = _model(
            potential, coupling, power_n, noise_piece,
            SimpleNamespace(noise_params=noise_params, osc_params=osc_params, dyn_params=dyn_params),
            channel, additive_noise)
        leaves = _dynamics.terms_of(dyn_params_v, additive_noise) & _dynamics.MOVES_REST
        boltzmann_T = _dynamics.value(dyn_params_v, "initial_temperature")
        if boltzmann_T > 0.0:
            from stochpend.model import initial as _initial

            try:
                _initial.check(oscillator, float(omega), boltzmann_T)
            except ValueError as exc:
                raise ValueError(str(exc)) from None
        if theta0_v is not None and Omega0 == 0.0 and not leaves and boltzmann_T == 0.0:
            _check_not_at_rest(oscillator, q, coupling, theta0_v)

        h_max, step_c, hist_bins, n_batches = _step_and_batches(h_max, step_c, hist_bins, n_batches, paths)

        e_max = _hist_E_max(hist_E_max, grid, noise=noise, D=D, tau=tau, omega=omega)

        _observables.check_windows(observables, grid)
        joint = _joint(joint_bins, joint_x_range, joint_Omega_max, oscillator=oscillator, omega=omega,
                       e_min=omega**2 * oscillator.energy_floor(q), e_max=e_max,
                       thermal=_thermal_Omega2(dyn_params_v, grid))
        return cls(
            noise=noise,
            D=D,
            tau=tau,
            omega=omega,
            paths=paths,
            t_max=t_max,
            times=tuple(float(x) for x in grid),
            seed=seed,
            theta0=theta0_v,
            Omega0=Omega0,
            xi0=xi0_v,
            h_max=h_max,
            step_c=step_c,
            hist_bins=hist_bins,
            hist_E_max=tuple(float(x) for x in e_max),
            n_batches=n_batches,
            potential=potential,
            power_n=power_n,
            coupling=coupling,
            omega_noise=omega_noise,
            observables=observables,
            noise_params=noise_params_v,
            osc_params=osc_params_v,
            dyn_params=dyn_params_v,
            joint_bins=joint[0],
            joint_x_range=joint[1],
            joint_Omega_max=joint[2],
            additive_noise=additive_noise,
        )


def _model(potential: Any, coupling: Any, power_n: Any, noise_piece: Any, given_params: Any,
           channel: Any, additive_noise: str | None) -> tuple[Any, int, Any, tuple, tuple, tuple]:
    """The oscillator, its validated power_n and record q, and the resolved parameters of the
    noise, the oscillator and the family's terms (one keyword space: ``given_params`` holds the
    caller's ``noise_params``, ``osc_params`` and ``dyn_params``)."""
    noise_params = given_params.noise_params
    osc_params = given_params.osc_params
    dyn_params = given_params.dyn_params
    oscillator = _oscillators.get(potential)
    if oscillator is None:
        _fail("potential", potential, f"one of {', '.join(_oscillators.names())}, or a model "
              "registered with stochpend.models.register")
    if not isinstance(coupling, str) or coupling not in _oscillators.COUPLINGS:
        _fail("coupling", coupling, f"one of {', '.join(_oscillators.COUPLINGS)}")
    power_n = _integer("power_n", power_n, f"power_n must be an integer in [1, {MAX_POWER_N}]", 1,
                       MAX_POWER_N)
    # The family's terms (stochpend.model.dynamics) share the keyword space: taken out first.
    try:
        given = dict(noise_params or {})
        dyn_given = dict(dyn_params or {})
    except (TypeError, ValueError):
        _fail("noise_params", noise_params, "a mapping of parameter names to numbers")
    for piece, kind in ((noise_piece, "noise"), (oscillator, "potential")):
        clash = sorted({q.name for q in _parameters.own(piece)} & set(_dynamics.names()))
        if clash:  # the family's terms own these names (stochpend.model.dynamics)
            _fail(kind, getattr(piece, "name", piece), f"it declares {clash[0]!r}, a name of the family's "
                  "terms (stochpend.model.dynamics): rename its parameter")
    channel_names = set(_dynamics.channel_parameters(channel))
    dyn_given.update({k: given.pop(k) for k in list(given) if k in _dynamics.names() or k in channel_names})
    dyn_params_v = _dynamics.resolve(dyn_given, channel)
    _check_channel(additive_noise, channel, dyn_params_v)
    noise_given, osc_given = _parameters.split(noise_piece, oscillator, given)
    if osc_params:
        try:
            osc_given.update(dict(osc_params))
        except (TypeError, ValueError):
            _fail("osc_params", osc_params, "a mapping of the oscillator's own parameters to numbers")
    noise_params_v = _parameters.resolve(noise_piece, noise_given)
    osc_params_v = _parameters.resolve(oscillator, osc_given, kind="potential")
    q = oscillator.record(SimpleNamespace(power_n=power_n, osc_params=osc_params_v))
    if oscillator.periodic and coupling == "position":
        if oscillator.builtin:
            _fail("coupling", coupling, f"the {potential}'s angle is periodic, so its noise can "
                  "only multiply the force (coupling='force')")
        _fail("coupling", coupling, f"model {potential!r} is periodic, so its noise can only "
              "multiply a periodic function (coupling='force')")
    return oscillator, power_n, q, noise_params_v, osc_params_v, dyn_params_v


def _step_and_batches(h_max: Any, step_c: Any, hist_bins: Any, n_batches: Any,
                      paths: int) -> tuple[float, float, int, int]:
    """The step control (h_max, step_c), the histograms' bins and the batch count, validated;
    the count lowered so that no batch is empty."""
    h_max = _finite("h_max", h_max, "h_max must be a finite number > 0 (the largest step)")
    if h_max <= 0:
        _fail("h_max", h_max, "h_max must be a finite number > 0 (the largest step)")
    step_c = _finite("step_c", step_c, "step_c must be a finite number >= 0 (0: fixed step)")
    if step_c < 0:
        _fail("step_c", step_c, "step_c must be a finite number >= 0 (0: fixed step)")
    hist_bins = _integer("hist_bins", hist_bins, "hist_bins must be an integer >= 1", 1)
    n_batches = _integer("n_batches", n_batches, "n_batches must be an integer >= 2", 2)
    n_batches = min(n_batches, paths)
    # Batches of equal size except the last; recompute the count so none is empty.
    n_batches = -(-paths // (-(-paths // n_batches)))
    return h_max, step_c, hist_bins, n_batches


def _checked_noise(noise: Any, D: Any, tau: Any, omega_noise: Any) -> tuple[Any, float, float | None, float | None]:
    """The noise's piece and its validated (D, tau, omega_noise): tau only for a colored noise,
    omega_noise only for one that uses it (its default from tau where not given)."""
    noise_piece = _noises.get(noise)
    if noise_piece is None:
        lower = noise.lower() if isinstance(noise, str) else None  # --noise OU: names are lower case
        _fail("noise", noise, f"one of {', '.join(_noises.names())}"
              + (f" (names are lower case: {lower!r})" if lower in _noises.names() else ""))
    D = _finite("D", D, "D must be a finite number >= 0 (the noise amplitude)")
    if D < 0:
        _fail("D", D, "D must be a finite number >= 0 (the noise amplitude)")
    if noise_piece.colored:
        if tau is None:
            _fail("tau", tau, f"{noise} noise needs tau, a finite number > 0 (its correlation time)")
        tau = _finite("tau", tau, "tau must be a finite number > 0 (the noise correlation time)")
        if tau <= 0:
            _fail(
                "tau",
                tau,
                "tau must be a finite number > 0 (the noise correlation time); "
                "use noise='white' for the tau -> 0 limit",
            )
    else:
        tau = None
    if noise_piece.uses_omega_noise:
        if omega_noise is None:
            # a noise that uses W is colored and gives its default (noises.base.Noise)
            assert noise_piece.default_omega_noise is not None and tau is not None
            omega_noise = noise_piece.default_omega_noise(tau)
            if not math.isfinite(omega_noise):
                _fail("tau", tau, "tau too small for the default omega_noise (it overflows); "
                      "give omega_noise")
        omega_noise = _finite(
            "omega_noise", omega_noise,
            "omega_noise must be a finite number > 0 (the harmonic noise's frequency W)")
        if omega_noise <= 0:
            _fail("omega_noise", omega_noise,
                  "omega_noise must be a finite number > 0 (the harmonic noise's frequency W)")
    elif omega_noise is not None:
        users = [n for n in _noises.names() if getattr(_noises.get(n), "uses_omega_noise", False)]
        _fail("omega_noise", omega_noise,
              f"omega_noise applies to noise={' or '.join(repr(n) for n in users)} only")
    return noise_piece, D, tau, omega_noise


def _output_grid(times: Any, n_times: Any, t_max: float) -> np.ndarray:
    """The output times: ``times`` validated, or ``n_times`` log-spaced from t_max/1000 to t_max
    (the C library's log10 and pow, :mod:`stochpend.numerics._hostmath`: the same bits on every x86-64)."""
    if times is None:
        n_times = _integer("n_times", n_times, f"n_times must be an integer in [1, {MAX_N_TIMES}]", 1,
                           MAX_N_TIMES)
        grid = _hostmath.geomspace(t_max * 1e-3, t_max, n_times) if n_times > 1 else np.array([t_max])
        grid[-1] = t_max
    else:
        try:
            grid = _float_array(times).ravel()
        except (TypeError, ValueError, OverflowError):
            _fail("times", times, "times must be a list of numbers in [0, t_max]")
        if grid.size == 0 or not np.all(np.isfinite(grid)):
            _fail("times", times, "times must be a non-empty list of finite numbers in [0, t_max]")
        if np.any(grid < 0) or np.any(grid > t_max):
            _fail("times", times, f"times must lie in [0, t_max] = [0, {t_max}]")
        if np.any(np.diff(grid) <= 0):
            _fail("times", times, "times must be strictly increasing")
    return grid


def _initial_values(theta0: Any, Omega0: Any, xi0: Any, noise_piece: Any) -> tuple[float | None, float, float | None]:
    """(theta0, Omega0, xi0) validated: None for 'uniform' and 'stationary'."""
    if isinstance(theta0, str):
        if theta0 != "uniform":
            _fail("theta0", theta0, "theta0 must be a finite number or 'uniform'")
        theta0_v: float | None = None
    elif theta0 is None:
        theta0_v = None
    else:
        theta0_v = _finite("theta0", theta0, "theta0 must be a finite number or 'uniform'")
    Omega0 = _finite("Omega0", Omega0, "Omega0 must be a finite number")
    if isinstance(xi0, str):
        if xi0 != "stationary":
            _fail("xi0", xi0, "xi0 must be a finite number or 'stationary'")
        xi0_v: float | None = None
    elif xi0 is None:
        xi0_v = None
    else:
        xi0_v = _finite("xi0", xi0, "xi0 must be a finite number or 'stationary'")
        if noise_piece.check_xi0 is not None:
            noise_piece.check_xi0(xi0_v)
    return theta0_v, Omega0, xi0_v


def _check_not_at_rest(oscillator: Any, q: Any, coupling: str, theta0_v: float) -> None:
    """Refuse a start at rest on a fixed point that the multiplicative noise cannot leave."""
    functions = oscillator.functions
    try:
        f = float(functions.force(theta0_v, q))
        g = theta0_v if coupling == "position" else float(functions.noise_shape(theta0_v, q))
    except OverflowError:  # |theta0| ** (2n - 1) beyond float: far from rest
        g = f = math.inf
    at_rest = abs(g) < 1e-12 and abs(f) < 1e-12
    if at_rest:
        _fail(
            "theta0",
            theta0_v,
            "(theta0, Omega0) is a fixed point that the multiplicative noise cannot "
            "leave; use theta0='uniform' or a nonzero Omega0",
        )


def _hist_E_max(hist_E_max: Any, grid: np.ndarray, *, noise: str, D: float, tau: float | None,
                omega: float) -> np.ndarray:
    """The energy histograms' upper edges, one per output time: given (one or one per time) or
    the default for the noise."""
    if hist_E_max is None:
        e_max = default_hist_E_max(grid, noise=noise, D=D, tau=tau, omega=omega)
    else:
        accepted = "hist_E_max must be a finite number > -omega**2, or one per output time"
        try:
            e_max = np.broadcast_to(_float_array(hist_E_max), grid.shape).copy()
        except (TypeError, ValueError, OverflowError):
            _fail("hist_E_max", hist_E_max, accepted)
        if not np.all(np.isfinite(e_max)) or np.any(e_max <= -(omega**2)):
            _fail("hist_E_max", hist_E_max, accepted)
    return e_max


def _additive_noise(name: Any) -> Any:
    """The generic additive channel's noise for ``additive_noise=name`` (None for unset or
    "white": the white channel, or OU by ``additive_tau``), or a one-line refusal listing the
    registered noises."""
    if name is None:
        return None
    noise = _noises.get(name)
    if noise is None:
        _fail("additive_noise", name, f"one of {', '.join(_noises.names())} (a registered noise's name)")
    return None if name in _dynamics.WHITE else noise


def _check_channel(name: str | None, noise: Any, pairs: tuple) -> None:
    """One-line refusals of the additive channel's parameters for ``additive_noise=name``."""
    tau_a = _dynamics.value(pairs, "additive_tau")
    W_a = _dynamics.value(pairs, "additive_omega_noise")
    if name == "white" and tau_a > 0.0:
        _fail("additive_tau", tau_a, "additive_noise='white' has no correlation time: give additive_tau=0 "
              "(or additive_noise='ou')")
    if name == "ou" and tau_a <= 0.0:
        _fail("additive_tau", tau_a, "additive_noise='ou' needs additive_tau > 0 (its correlation time)")
    if W_a != 0.0 and (noise is None or not noise.uses_omega_noise):
        users = [n for n in _noises.names() if getattr(_noises.get(n), "uses_omega_noise", False)]
        _fail("additive_omega_noise", W_a, "additive_omega_noise applies to additive_noise="
              f"{' or '.join(repr(n) for n in users)} only")
    if noise is None:
        return
    if noise.colored and tau_a <= 0.0:
        _fail("additive_tau", tau_a, f"additive_noise={name!r} is colored: it needs additive_tau > 0 "
              "(its correlation time)")
    if noise.uses_omega_noise:
        W = _dynamics.channel_omega_noise(noise, pairs)
        if not (math.isfinite(W) and W > 0.0):
            _fail("additive_omega_noise", W_a, "additive_tau too small for the default (it overflows): give "
                  "additive_omega_noise > 0")


#: The most bins of the joint histogram along x or Omega (its per-batch counts and sums of
#: squares are held per output time: 3 (nx + 2) (nOmega + 2) integers).
MAX_JOINT_BINS = 500


def _thermal_Omega2(dyn_params: tuple, times: np.ndarray) -> np.ndarray:
    """The scale of Omega**2 that the family's additive noise and Boltzmann start give at each
    time (stochpend.model.dynamics): the temperature D_a/(2 gamma) with damping, D_a t without, and
    the initial temperature; zeros without them."""
    gamma = _dynamics.value(dyn_params, "gamma")
    d_a = _dynamics.value(dyn_params, "additive_D")
    heat = np.full(np.shape(times), d_a / (2.0 * gamma)) if gamma > 0 else d_a * np.asarray(times)
    return np.maximum(heat, _dynamics.value(dyn_params, "initial_temperature"))


def _joint(bins: Any, x_range: Any, Omega_max: Any, *, oscillator: Any, omega: float, e_min: float,
           e_max: np.ndarray, thermal: np.ndarray) -> tuple[tuple, tuple, tuple]:
    """The joint histogram's validated fields (``joint_bins``, ``joint_x_range``,
    ``joint_Omega_max``); empty without ``bins``."""
    if bins is None or (isinstance(bins, (tuple, list)) and len(bins) == 0):
        for name, value in (("joint_x_range", x_range), ("joint_Omega_max", Omega_max)):
            if value is not None and not (isinstance(value, (tuple, list)) and len(value) == 0):
                _fail(name, value, "it applies to the joint histogram only: give joint_bins too")
        return (), (), ()
    accepted = f"joint_bins must be two integers (nx, nOmega), each in [1, {MAX_JOINT_BINS}]"
    if isinstance(bins, (str, bytes)) or not hasattr(bins, "__len__") or len(bins) != 2:
        _fail("joint_bins", bins, accepted)
    nx, nO = (_integer("joint_bins", b, accepted, 1, MAX_JOINT_BINS) for b in bins)
    if x_range is None or (isinstance(x_range, (tuple, list)) and len(x_range) == 0):
        x_v: tuple[float, ...] = ()
        if not oscillator.periodic and omega == 0.0:
            _fail("joint_x_range", x_range, "give (lo, hi): at omega = 0 there is no default x range")
    else:
        accepted = "joint_x_range must be two finite numbers lo < hi"
        if oscillator.periodic:
            _fail("joint_x_range", x_range, "the angle of a periodic oscillator is binned over "
                  "[-pi, pi): leave joint_x_range out")
        if isinstance(x_range, (str, bytes)) or not hasattr(x_range, "__len__") or len(x_range) != 2:
            _fail("joint_x_range", x_range, accepted)
        x_v = tuple(_finite("joint_x_range", v, accepted) for v in x_range)
        if not x_v[0] < x_v[1] or not math.isfinite(x_v[1] - x_v[0]):
            _fail("joint_x_range", x_range, accepted)
    if Omega_max is None:
        # Every energy the energy histogram covers: Omega**2 / 2 <= E_max - E_min, and 8
        # thermal standard deviations of the family's additive noise.
        with np.errstate(over="ignore", invalid="ignore"):
            w = np.maximum(np.sqrt(2.0 * (np.asarray(e_max) - e_min)), 8.0 * np.sqrt(thermal))
        w = np.minimum(w, 1e150)
    else:
        accepted = "joint_Omega_max must be a finite number > 0, or one per output time"
        try:
            w = np.broadcast_to(_float_array(Omega_max), np.shape(e_max)).copy()
        except (TypeError, ValueError, OverflowError):
            _fail("joint_Omega_max", Omega_max, accepted)
        if not np.all(np.isfinite(w)) or np.any(w <= 0) or np.any(w > 1e150):
            _fail("joint_Omega_max", Omega_max, accepted)
    return (nx, nO), x_v, tuple(float(v) for v in w)


def joint_grid(config: SimulationConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """Bin edges of the joint (x, Omega) histogram, ``(x_edges, Omega_edges)`` of shapes
    (n_times, nx + 1) and (n_times, nOmega + 1), uniform; None without one.

    x: a periodic oscillator's angle over [-pi, pi) (the convention of its steps); otherwise
    ``joint_x_range``, by default the harmonic oscillator's turning points at the Omega range,
    +-joint_Omega_max/omega. Omega: [-joint_Omega_max, joint_Omega_max], by default the
    velocities of every energy the energy histogram covers (sqrt(2 (hist_E_max - E_min))), or
    8 thermal standard deviations of the family's additive noise where that is wider.
    """
    if not config.joint_bins:
        return None
    nx, nO = config.joint_bins
    w = np.asarray(config.joint_Omega_max, dtype=np.float64)[:, None]
    oscillator = _oscillators.get(config.potential)
    assert oscillator is not None, config.potential
    if oscillator.periodic:
        lo, hi = np.full_like(w, -math.pi), np.full_like(w, math.pi)
    elif config.joint_x_range:
        lo, hi = np.full_like(w, config.joint_x_range[0]), np.full_like(w, config.joint_x_range[1])
    else:
        hi = w / config.omega
        lo = -hi
    u = np.linspace(0.0, 1.0, nx + 1)[None, :]
    x_edges = lo + (hi - lo) * u
    x_edges[:, -1] = hi[:, 0]
    v = np.linspace(0.0, 1.0, nO + 1)[None, :]
    Omega_edges = -w + 2.0 * w * v
    Omega_edges[:, -1] = w[:, 0]
    return x_edges, Omega_edges


def joint_cells(config: SimulationConfig) -> int:
    """Cells of the joint histogram with its outside rows and columns, (nx + 2) (nOmega + 2);
    0 without one."""
    if not config.joint_bins:
        return 0
    return (config.joint_bins[0] + 2) * (config.joint_bins[1] + 2)


def hist_columns(config: SimulationConfig) -> int:
    """Columns of a run's histogram counts per output time (``EnsembleSums.hist``): the energy
    histogram's underflow, bins and overflow, then, with a joint histogram, its counts, their
    per-batch squares and their per-batch products with the batch's finite paths, each over
    the :func:`joint_cells` (``stochpend.model.power_sums``: the errors)."""
    return config.hist_bins + 2 + 3 * joint_cells(config)


def default_hist_E_max(times: np.ndarray, *, noise: str, D: float, tau: float | None, omega: float) -> np.ndarray:
    """Upper edge of the energy histogram at each time: far in the tail of the expected law.

    Uses the white-noise growth D t/4 for white noise and, for OU noise, the crossover
    estimate (sqrt(D tau**2 phi t + 1) - 1)/(2 tau**2 phi) with phi = 2.19, which follows
    D t/4 early and the t**(1/2) law late; 30 times that scale leaves < 1e-6 of the mass out.
    The result is capped at 1e300, so that extreme (D, t) give a finite, if useless, range.
    """
    t = np.asarray(times, dtype=np.float64)
    D, omega = np.float64(D), np.float64(omega)
    tau = None if tau is None else np.float64(tau)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        white = D * t / 4.0
        if noise == "white" or tau is None:
            scale = white
        else:
            phi = 2.19
            scale = (np.sqrt(D * tau**2 * phi * t + 1.0) - 1.0) / (2.0 * tau**2 * phi)
            # tau**2 underflowing to 0 gives 0/0: the tau -> 0 limit is the white-noise scale
            scale = np.where(np.isfinite(scale), scale, white)
        e_max = omega**2 + 1.0 + 30.0 * scale
    return np.minimum(np.nan_to_num(e_max, nan=1e300), 1e300)


def hist_edges(config: SimulationConfig) -> np.ndarray:
    """Bin edges of the energy histogram, shape (n_times, hist_bins + 1).

    Edges are uniform in sqrt(E - E_min), E_min = -omega**2 for the pendulum, so that the
    bins are narrow near the bottom of the range, where the law diverges like E**(-1/2).
    """
    oscillator = _oscillators.get(config.potential)
    assert oscillator is not None, config.potential  # validated when the config was built
    e_min = config.omega**2 * oscillator.energy_floor(oscillator.record(config))
    u = np.linspace(0.0, 1.0, config.hist_bins + 1) ** 2
    e_max = np.asarray(config.hist_E_max)[:, None]
    return e_min + (e_max - e_min) * u[None, :]
