"""The paper's predictions at one time, as table rows (the CLI renders them with rich).

Each row names the regime (which approximation), the quantity, its value at the requested
time, the paper's equation label and the condition under which the prediction applies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from stochpend.text._docs import documented
from stochpend.theory import laws
from stochpend.theory.laws import _check_D, _check_omega, _check_tau, _fail, _scalar

__all__ = ["Prediction", "format_table", "predictions"]

NOISES = ("white", "ou")


@dataclass(frozen=True)
class Prediction:
    """One row of the predictions table.

    Attributes
    ----------
    regime : str
        The approximation and where it comes from, e.g. ``"white noise, averaged FPE (moyblanc)"``.
    quantity : str
        ``"<E>"``, ``"<E^2>"``, ``"S"``, ``"F"``, ``"t_c"``, ``"phi"``.
    value : float
        The predicted value at the requested time.
    equation : str
        The paper's equation label(s).
    validity : str
        Where the prediction applies, e.g. ``"t >> t_c = 1/(D tau^2)"``.
    note : str
        Caveats (``""`` if none).
    """

    regime: str
    quantity: str
    value: float
    equation: str
    validity: str
    note: str = ""


@documented  # help() shows the signature's defaults and the paper's equation numbers
def predictions(
    *,
    noise: str,
    D: float,
    tau: float | None = None,
    omega: float = 1.0,
    t: float,
    bfpe: bool = False,
) -> list[Prediction]:
    """Every prediction of the paper for ``noise`` at time ``t``.

    Parameters
    ----------
    noise : {"white", "ou"}
        Noise type (as in the simulator).
    D : float
        Noise amplitude, >= 0.
    tau : float, optional
        OU correlation time, > 0; required for ``noise="ou"``, ignored for white noise.
    omega : float, optional
        Pendulum frequency (>= 0). It does not enter the asymptotic laws; it is validated and
        recorded. The B.F.P.E. rows are for ``omega = 0`` whatever its value.
    t : float
        Time, >= 0 (> 0 when ``bfpe`` is true).
    bfpe : bool, optional
        Also solve the averaged B.F.P.E. (`avbfpe`) numerically up to ``t`` (about 0.2 s)
        and add its ``<E>``, ``<E^2>``, ``phi``, ``S``, ``F``.

    Returns
    -------
    list of Prediction
        White noise: ``<E>``, ``<E^2>``, ``S``, ``F``. OU noise: the white-like short-time
        ``<E>``, ``t_c``, first-order averaging (known-wrong prefactors), second-order
        averaging, the B.F.P.E. constant-flatness crossover ``<E>`` with ``phi = PHI_INF``,
        the derived long-time B.F.P.E. ``<E>`` with its first correction, and optionally the
        numerical B.F.P.E.

    Raises
    ------
    ValueError
        One line naming the parameter, its value and what is accepted.
    """
    if not isinstance(noise, str) or noise.lower() not in NOISES:
        _fail("noise", noise, f"one of {', '.join(NOISES)}")
    noise = noise.lower()
    D = _check_D(D)
    omega = _check_omega(omega)
    t = _scalar("t", t, "t must be a finite number >= 0")
    if t < 0:
        _fail("t", t, "t must be a finite number >= 0")
    if noise == "white":
        return _white_rows(t, D)

    tau = _check_tau(tau)
    rows = _ou_rows(t, D, tau)
    if bfpe:
        if t <= 0:
            _fail("t", t, "t must be > 0 to solve the B.F.P.E. (bfpe=True)")
        rows += _bfpe_rows(t, D, tau)
    return rows


def _white_rows(t: float, D: float) -> list[Prediction]:
    """White noise: <E>, <E^2>, S, F of the averaged FPE (moyblanc, eq:pdfEblanc)."""
    reg = "white noise, averaged FPE (moyblanc, eq:pdfEblanc)"
    valid = "all t, once theta is uniformly spread (any omega)"
    return [
        Prediction(reg, "<E>", float(laws.white_mean_E(t, D=D)), "eq:scalEblanc", valid),
        Prediction(
            reg, "<E^2>", float(laws.white_mean_E2(t, D=D)), "eq:pdfEblanc", valid, "3 (D t)^2/16"
        ),
        Prediction(reg, "S", laws.white_skewness(), "eq:skewEblanc", valid, "5/sqrt(3), raw moments"),
        Prediction(reg, "F", laws.white_flatness(), "eq:flatEblanc", valid, "35/3, raw moments"),
    ]


def _ou_rows(t: float, D: float, tau: float) -> list[Prediction]:
    """OU noise: t_c, the white-like law, first- and second-order averaging and the
    B.F.P.E.'s closed-form laws."""
    rows: list[Prediction] = []
    t_c = laws.crossover_time(D=D, tau=tau)
    rows.append(
        Prediction(
            "OU, crossover time",
            "t_c",
            t_c,
            "tpcross",
            "order of magnitude",
            "1/(D tau^2); the bend of <E>(t) spreads over decades around it",
        )
    )
    rows.append(
        Prediction(
            "OU, white-like short-time law",
            "<E>",
            float(laws.white_mean_E(t, D=D)),
            "eq:scalEblanc",
            "tau << t << t_c",
            "D t/4; for t << tau (stationary xi) <E> ~ D t^2/(8 tau) instead",
        )
    )
    reg1 = "OU, first-order averaging (PDFav1)"
    rows += [
        Prediction(
            reg1,
            "<E>",
            float(laws.ou1_mean_E(t, D=D, tau=tau)),
            "diff1",
            "t >> t_c",
            "known-wrong prefactor 1/sqrt(pi) (paper: disagrees with simulations)",
        ),
        Prediction(
            reg1,
            "<E^2>",
            float(laws.ou1_mean_E2(t, D=D, tau=tau)),
            "quad1",
            "t >> t_c",
            "known-wrong prefactor 1/2",
        ),
    ]
    reg2 = "OU, second-order averaging (eq:pdfEcolor)"
    rows += [
        Prediction(
            reg2,
            "<E>",
            float(laws.ou2_mean_E(t, D=D, tau=tau)),
            "eq:scalEcolor",
            "t >> t_c",
            "0.33799 (D t/tau^2)^(1/2)",
        ),
        Prediction(
            reg2,
            "<E^2>",
            float(laws.ou2_mean_E2(t, D=D, tau=tau)),
            "eq:scalE2color",
            "t >> t_c",
            "D t/(4 tau^2)",
        ),
        Prediction(
            reg2,
            "S",
            laws.ou2_skewness(),
            "eq:skewEcolor",
            "t >> t_c",
            "typo-corrected closed form, 2.027935",
        ),
        Prediction(reg2, "F", laws.ou2_flatness(), "eq:flatEcolor", "t >> t_c", "5"),
    ]
    rows.append(
        Prediction(
            "OU, B.F.P.E. with constant flatness phi = phi_inf",
            "<E>",
            float(laws.phi_crossover_mean_E(t, D=D, tau=tau, phi=laws.PHI_INF)),
            "idquadr, deflatness",
            "all t (interpolation; exact limits t << t_c and t >> t_c; omega = 0)",
            f"phi_inf = {laws.PHI_INF:.6f} (second-order value of <E^2>/<E>^2)",
        )
    )
    rows.append(
        Prediction(
            "OU, B.F.P.E. long-time law (derived: similarity solution + first correction)",
            "<E>",
            float(laws.bfpe_longtime_mean_E(t, D=D, tau=tau, corrected=True)),
            "avbfpe",
            "t >> t_c (omega = 0)",
            f"c (D t/tau^2)^(1/2) - a/tau^2, c = Gamma(3/4)/Gamma(1/4), "
            f"a = {laws.bfpe_longtime_correction():.6f}",
        )
    )
    return rows


def _bfpe_rows(t: float, D: float, tau: float) -> list[Prediction]:
    """The averaged B.F.P.E. (avbfpe) solved numerically up to t: <E>, <E^2>, phi, S, F."""
    from stochpend.theory.bfpe import solve_bfpe

    ds = solve_bfpe(D=D, tau=tau, t_max=t, times=[t])
    regb = "OU, B.F.P.E. solved numerically (avbfpe, omega = 0)"
    valid_b = "all t (omega = 0; an approximation of the OU dynamics)"
    get = lambda name: float(ds[name].values[-1])  # noqa: E731
    rows = [
        Prediction(regb, "<E>", get("mean_E"), "avbfpe", valid_b),
        Prediction(regb, "<E^2>", get("mean_E2"), "avbfpe, idquadr", valid_b),
        Prediction(regb, "phi", get("phi"), "deflatness", valid_b, f"-> {laws.PHI_INF:.6f} for t >> t_c"),
        Prediction(
            regb, "S", get("skewness"), "avbfpe", valid_b, f"-> {laws.OU2_SKEWNESS:.6f} for t >> t_c"
        ),
        Prediction(
            regb, "F", get("flatness"), "avbfpe", valid_b, f"-> {laws.OU2_FLATNESS:.6g} for t >> t_c"
        ),
    ]
    return rows


def _fmt(v: float) -> str:
    if math.isinf(v):
        return "inf"
    return f"{v:.6g}"


def format_table(rows: list[Prediction]) -> str:
    """Plain-text table of prediction rows (fixed-width columns, one row per line).

    Parameters
    ----------
    rows : list of Prediction
        As returned by :func:`predictions`.

    Returns
    -------
    str
        Header, rule, then one line per row: regime, quantity, value, equation, validity,
        and the note if any.
    """
    header = ("regime", "quantity", "value", "equation", "validity", "note")
    table = [header] + [(r.regime, r.quantity, _fmt(r.value), r.equation, r.validity, r.note) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    lines = []
    for j, row in enumerate(table):
        lines.append("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip())
        if j == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)
