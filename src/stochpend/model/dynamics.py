"""The family's terms beside the oscillator and its parametric noise, declared once.

    dx/dt = Omega
    dOmega/dt = -gamma Omega - omega**2 U'(x) - (xi(t) + eps cos(nu_p t)) G(x)
                + F + A cos(nu t + phi) + xi_a(t)

The terms damping, torque, drive and parametric are the entries of :data:`stochpend.terms.TABLE`
(one file each: its parameters, its kick over a step, its step bound); the additive noise xi_a
is the channel below. Each parameter is a :class:`stochpend.model.parameters.Parameter` of
:data:`FAMILY` (the table's, then the channel's), so the Python API takes
it as a keyword (``simulate(gamma=0.5, additive_D=0.2)``), the command line as ``--param
gamma=0.5``, a sweep file as a key, and the configuration (``SimulationConfig.dyn_params``, the
values that differ from their defaults), checkpoints, NetCDF attributes, ``show`` and ``list``
carry it, exactly as a noise's own parameters.

A term that is zero is not compiled: a kernel is specialised for the terms that are on
(:attr:`stochpend.engine.integrator.KernelSpec.terms`), so a run with every term zero runs today's kernel,
bit for bit (the golden fixture).

The additive noise xi_a is white, <xi_a(t) xi_a(s)> = D_a delta(t - s) (the package's
convention for white noise, :mod:`stochpend.noises.white`), independent of xi: its normals are
Philox draws of their own (``rng.N_ADDITIVE + k`` for step k). With damping and no other force
its stationary law is Boltzmann at T = D_a / (2 gamma) (:mod:`stochpend.theory.family`).

With ``additive_tau`` tau_a > 0 it is an Ornstein-Uhlenbeck noise instead, in the convention of
:mod:`stochpend.noises.ou`: <xi_a(t) xi_a(s)> = D_a/(2 tau_a) exp(-|t - s|/tau_a), so S(0) = D_a
and tau_a -> 0 is the white channel of intensity D_a: the channel below with the noise "ou".

``additive_noise`` (a setting of :class:`stochpend.model.settings.SimulationConfig`) makes xi_a ANY
registered noise (:mod:`stochpend.noises`: ``"ou"``, ``"harmonic"``, ``"dichotomous"``, a
user's): the term "additive_noise", one channel for every coloured noise (issue 33, item 5: the
Ornstein-Uhlenbeck one had a channel of its own until then, whose numbers differed only in
their random streams). Unset or ``"white"`` with tau_a = 0 is the white channel above: its
noise enters the exact Ornstein-Uhlenbeck flow of Omega with the damping (the Boltzmann law of
the damped harmonic oscillator at every gamma h), not the kick, so it stays a term of its own.
The channel's parameter record is the
noise's own :meth:`~stochpend.noises.Noise.record`, with its names mapped onto the channel
(:func:`channel_record`): D -> ``additive_D``, tau -> ``additive_tau``, omega_noise ->
``additive_omega_noise`` (0: the noise's ``default_omega_noise(tau_a)``), and each parameter p the
noise declares for itself -> ``additive_<p>``. Its random numbers are the noise's own draws
(init, draw, at_event) under the channel's Philox key (:func:`stochpend.numerics.rng.additive_key`), so
they are independent of xi's and of the white channel's, and keyed by (seed, path, step)
alone. Its state (xi_a, aux_a) is per path (the chunk arrays ``xi_a``, ``aux_a``); the noise's
exact step gives the integral of xi_a over the step, which enters the kick as the parametric
noise's integral does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from stochpend.model.parameters import Parameter
from stochpend.model.terms import TABLE

__all__ = ["FAMILY", "MOVES_REST", "POSITION", "RECORD", "TERMS", "additive_arrays", "channel", "channel_name", "channel_parameters",
           "channel_record", "names", "record", "terms_of", "terms_of_config"]


@dataclass(frozen=True)
class Dynamics:
    """The piece that declares the family's terms (``parameters``, as a noise declares its own)."""

    name: str
    parameters: tuple[Parameter, ...]


#: The additive noise channel's parameters and the initial temperature (the table's terms'
#: parameters come first: :data:`stochpend.terms.TABLE`).
_CHANNEL = (
    Parameter("additive_D", 0.0, "intensity D_a of the additive noise, S(0) = D_a (white: <xi_a xi_a'> = "
              "D_a delta; see additive_tau)", low=0.0),
    Parameter("initial_temperature", 0.0, "start from the Boltzmann law at this temperature (0: theta0, "
              "Omega0 as given; stochpend.model.initial)", low=0.0),
    Parameter("additive_tau", 0.0, "correlation time tau_a of the additive noise: 0 white, > 0 "
              "Ornstein-Uhlenbeck, <xi_a xi_a'> = D_a/(2 tau_a) exp(-|t - t'|/tau_a)", low=0.0),
    Parameter("additive_omega_noise", 0.0, "the additive noise's frequency W_a, a noise that takes "
              "omega_noise (additive_noise='harmonic'); 0: its default (2/tau_a)", low=0.0),
)

FAMILY = Dynamics("family", (*(p for term in TABLE for p in term.parameters), *_CHANNEL))

_ORDER = tuple(p.name for p in FAMILY.parameters)
_DEFAULTS = {p.name: p.default for p in FAMILY.parameters}

#: The terms a kernel can be specialised for, and the parameter that switches each on. The
#: additive noise is one of two terms (:func:`terms_of`): "additive", the white channel, or
#: "additive_noise", the generic channel of any coloured noise (OU by ``additive_tau`` > 0).
TERMS = {**{term.name: term.switch for term in TABLE}, "additive": "additive_D", "additive_noise": "additive_D"}

#: The terms that push a path at rest: the table's forces and the additive channel.
MOVES_REST = frozenset({term.name for term in TABLE if term.moves_rest} | {"additive", "additive_noise"})

#: ``additive_noise`` names that select the white channel (with ``additive_tau`` = 0), the exact
#: Ornstein-Uhlenbeck flow of Omega, rather than the generic channel (issue 33, item 5).
WHITE = (None, "white")


def names() -> tuple[str, ...]:
    """The family's parameter names (keywords, ``--param`` names, sweep keys)."""
    return _ORDER


def resolve(values: dict[str, Any], noise: Any = None) -> tuple[tuple[str, float], ...]:
    """Validate the family's parameters among ``values`` and return those that differ from
    their defaults as sorted (name, float) pairs: what a configuration stores (empty for a run
    of the paper's model, so its configuration, hash and file are what they were). ``noise``:
    the generic channel's noise, whose own parameters ``additive_<p>`` are accepted too."""
    declared = {p.name: p for p in FAMILY.parameters}
    own = channel_parameters(noise)
    defaults = {**_DEFAULTS, **{name: p.default for name, p in own.items()}}
    out = {}
    for name, value in values.items():
        if name in own:
            try:
                out[name] = own[name].check(value)
            except ValueError as exc:  # the message names the channel's parameter
                raise ValueError(f"{name}{str(exc)[len(own[name].name):]}") from None
        else:
            out[name] = declared[name].check(value)
    return tuple(sorted((name, v) for name, v in out.items() if v != defaults[name]))


def channel_parameters(noise: Any) -> dict[str, Any]:
    """The parameters the generic channel's ``noise`` declares for itself, by their channel
    names ``additive_<p>`` (:class:`stochpend.model.parameters.Parameter` values); empty for none."""
    from stochpend.model.parameters import own

    return {f"additive_{p.name}": p for p in own(noise)} if noise is not None else {}


def value(pairs: tuple[tuple[str, float], ...], name: str) -> float:
    return dict(pairs).get(name, _DEFAULTS[name])


def channel_name(pairs: tuple[tuple[str, float], ...], additive_noise: str | None = None) -> str | None:
    """The generic channel's noise of a run: ``additive_noise``, or "ou" when it is unset and
    ``additive_tau`` > 0 (the Ornstein-Uhlenbeck additive noise is the channel's "ou", one
    mechanism with every other coloured noise); None for the white channel (unset or "white"
    with ``additive_tau`` = 0)."""
    if additive_noise is None:
        return "ou" if value(pairs, "additive_tau") > 0.0 else None
    return None if additive_noise in WHITE else additive_noise


def terms_of(pairs: tuple[tuple[str, float], ...], additive_noise: str | None = None) -> frozenset[str]:
    """The terms that are on (their parameter nonzero): what a kernel is specialised for. The
    additive noise is "additive" (white, the exact Ornstein-Uhlenbeck flow of Omega) when
    :func:`channel_name` is None, else "additive_noise" (the generic channel: OU when
    ``additive_tau`` > 0 and ``additive_noise`` is unset, else that noise)."""
    generic = channel_name(pairs, additive_noise) is not None
    return frozenset(term for term, name in TERMS.items()
                     if value(pairs, name) != 0.0 and (term != "additive" or not generic)
                     and (term != "additive_noise" or generic))


def terms_of_config(config: Any) -> frozenset[str]:
    """:func:`terms_of` of a configuration (its ``dyn_params`` and ``additive_noise``)."""
    return terms_of(getattr(config, "dyn_params", ()), getattr(config, "additive_noise", None))


#: The names of the kernels' record of the family's terms (:func:`record`): the table's
#: parameters, then the additive channel's D_a, sigma_a and tau_a (the initial temperature is
#: used on the host, stochpend.model.initial).
RECORD = (*(p.name for term in TABLE for p in term.parameters), "additive_D", "sigma_a", "additive_tau")

#: Where the kernels read each of :data:`RECORD` in the record (``d[POSITION["gamma"]]``).
POSITION = {name: i for i, name in enumerate(RECORD)}


def record(config: Any) -> tuple[float, ...]:
    """The kernels' record of the family's terms, the values of :data:`RECORD`: the table's
    parameters in declared order, D_a, then sigma_a = sqrt(D_a / (2 gamma)) (the additive white
    noise's stationary velocity scale, sqrt(T); sqrt(D_a) without damping), then the additive
    noise's correlation time tau_a (0: white)."""
    pairs = getattr(config, "dyn_params", ())
    gamma, D_a = float(value(pairs, "gamma")), float(value(pairs, "additive_D"))
    sigma = math.sqrt(D_a / (2.0 * gamma)) if gamma > 0 else math.sqrt(D_a)
    derived = {"sigma_a": sigma}
    return tuple(derived[name] if name in derived else float(value(pairs, name)) for name in RECORD)


def channel(config: Any) -> Any:
    """The generic additive channel's noise (:class:`stochpend.noises.Noise`) of a run with it
    on (``additive_noise`` neither unset, "white" nor "ou", and ``additive_D`` > 0), else None."""
    if "additive_noise" not in terms_of_config(config):
        return None
    from stochpend.model import noises

    name = channel_name(getattr(config, "dyn_params", ()), getattr(config, "additive_noise", None))
    assert name is not None  # the term is on
    return noises.get(name)


def additive_arrays(config: Any) -> tuple[str, ...]:
    """The per-path arrays of the run's additive channel, placed after the others in the
    kernels' state and written to its checkpoints: ``("xi_a", "aux_a")`` for the channel of a
    coloured noise, none for any other run."""
    return ("xi_a", "aux_a") if "additive_noise" in terms_of_config(config) else ()


def channel_omega_noise(noise: Any, pairs: tuple[tuple[str, float], ...]) -> float:
    """The channel's W_a: ``additive_omega_noise``, or the noise's default at tau_a when 0."""
    W = float(value(pairs, "additive_omega_noise"))
    if W == 0.0 and noise.uses_omega_noise and noise.default_omega_noise is not None:
        W = float(noise.default_omega_noise(value(pairs, "additive_tau")))
    return W


def channel_view(config: Any, noise: Any) -> SimpleNamespace:
    """The configuration as the channel's ``noise`` reads it (its shared D, tau, omega_noise and
    its own parameters, from the channel's names): what :meth:`Noise.record` takes."""
    pairs = getattr(config, "dyn_params", ())
    given = dict(pairs)
    own = tuple(sorted((name[len("additive_"):], float(given.get(name, p.default)))
                       for name, p in channel_parameters(noise).items()))
    tau = float(value(pairs, "additive_tau"))
    return SimpleNamespace(D=float(value(pairs, "additive_D")), tau=tau if noise.colored else 0.0,
                           omega_noise=channel_omega_noise(noise, pairs), noise_params=own)


def channel_record(config: Any) -> tuple[float, ...]:
    """The generic channel's noise record (``Noise.record`` of the noise, with D -> additive_D,
    tau -> additive_tau, omega_noise -> additive_omega_noise, p -> additive_<p>): a tuple of
    float64 in the order of the noise's ``parameters``. Empty for a run without the channel."""
    noise = channel(config)
    if noise is None:
        return ()
    return noise.record(channel_view(config, noise))
