"""The paper's equation numbers, for text a reader compares with the printed paper.

The code and the docs cite the LaTeX source's ``\\label`` names (``eq:scalEcolor``, ``avbfpe``):
stable, searchable in the source, but not what a reader of the published paper sees. The
report and the CLI's help show the printed number too, ``Eq. (49)``, from :data:`EQUATIONS`,
which :func:`number_equations` computes from the source with the numbering rules of its class
(revtex4: one number per ``equation`` and per ``eqnarray`` row without ``\\nonumber``, in
order; after ``\\appendix`` the numbers restart as A1, A2, ...).
``tests/theory/test_paper.py`` recomputes the table from the source when the paper's folder is
present, so the two cannot drift apart.
"""

from __future__ import annotations

import re

__all__ = ["EQUATIONS", "cite", "eq", "number_equations", "with_numbers"]

_ENV = re.compile(r"\\begin\{(equation|eqnarray)\}(.*?)\\end\{\1\}", re.S)
_LABEL = re.compile(r"\\label\{([^}]*)\}")


def number_equations(tex: str) -> dict[str, str]:
    """``{label: number}`` of every labelled equation of a revtex4 source (module docstring)."""
    appendix_at = tex.find("\\appendix")
    out: dict[str, str] = {}
    main = appendix = 0
    source = re.sub(r"(?m)(?<!\\)%.*$", "", tex)  # comments are not typeset
    appendix_at = source.find("\\appendix")
    for m in _ENV.finditer(source):
        rows = [m.group(2)] if m.group(1) == "equation" else re.split(r"\\\\", m.group(2))
        for row in rows:
            if m.group(1) == "eqnarray" and ("\\nonumber" in row or not row.strip()):
                continue
            if appendix_at >= 0 and m.start() > appendix_at:
                appendix += 1
                number = f"A{appendix}"
            else:
                main += 1
                number = str(main)
            for label in _LABEL.findall(row):
                out[label] = number
    return out


#: ``{label: printed number}`` of Mallick & Marcq (2004), computed by :func:`number_equations`
#: from the LaTeX source (checked against it in tests/theory/test_paper.py).
EQUATIONS: dict[str, str] = {
    "dynOmega": "1", "dyntheta": "2", "defenergie": "3", "defbruitblanc": "4", "FPblanc": "5",
    "moyblanc": "6", "eq:pdfOmegablanc": "7", "eq:pdfEblanc": "8", "eq:scalEblanc": "9",
    "eq:skewEblanc": "10", "eq:flatEblanc": "11", "defalpha": "12", "correlationOU": "17",
    "eqOU": "18", "dyncolOmega": "19", "dyncoltheta": "20", "OU": "21", "FPcolor": "22",
    "average0": "24", "defE1": "29", "dyncolE1": "30", "dyncol2theta": "31", "OU2": "32",
    "FPcolor2": "33", "FPav1": "34", "average1": "35", "OUaverage1": "36", "PDFav1": "37",
    "diff1": "38", "quad1": "39", "dyncolU2": "40", "defZ": "41", "dynZ0": "42", "OmgZ": "43",
    "dyncolZ": "44", "FPcolor3": "47", "FPav2": "48", "average2": "49", "ZOU": "50",
    "LangeffZ": "51", "average2eta": "52", "eq:pdfEcolor": "53", "eq:scalEcolor": "54",
    "eq:scalE2color": "55", "eq:skewEcolor": "56", "eq:flatEcolor": "57", "tpcross": "58",
    "FPapprox1": "59", "FPcumul": "60", "defL0": "61", "defL1": "62", "bfpe": "63", "avbfpe": "64",
    "idquadr": "65", "quadbfpe": "66", "deflatness": "67", "idmat": "A1", "defTn": "A2",
    "recurrence": "A4", "solrecurrence": "A9", "defgotH1": "A12", "defgotH2": "A13",
}


def cite(label: str) -> str:
    """``"Eq. (49) [eq:scalEcolor]"`` for a label of the paper, the label alone if unknown."""
    number = EQUATIONS.get(label)
    return f"Eq. ({number}) [{label}]" if number else label


def eq(*labels: str) -> str:
    """``"eq. 18"`` for one label, ``"eqs. 49, 50"`` for several: the printed numbers, in the
    form the command line's help cites them ("... (eq. 18)"). An unknown label is a KeyError, so
    that a typo fails when the help is built, not in front of a reader."""
    numbers = [EQUATIONS[label] for label in labels]
    return ("eq. " if len(numbers) == 1 else "eqs. ") + ", ".join(numbers)


#: Labels that are also ordinary words of the text ("OU noise"): never replaced in prose.
_WORDS = {"OU"}
_CITED = re.compile(r"(Eqs?\.\s*)?`?(" + "|".join(
    re.escape(k) for k in sorted(set(EQUATIONS) - _WORDS, key=len, reverse=True))
    + r")`?(?!\w|:\w)")
_LIST = re.compile(r"\s*(?:[,–-]|and)\s*")


def with_numbers(text: str) -> str:
    """``text`` with every label of the paper replaced by its printed number: "eq:scalEblanc"
    -> "Eq. (9)", "Eqs. dynOmega, dyntheta" -> "Eqs. (1), (2)", "eq:scalEblanc–eq:flatEblanc"
    -> "Eq. (9)–(11)"; a label that follows "Eq."/"Eqs." or another cited label in a list keeps
    no second "Eq."."""
    out: list[str] = []
    last = 0
    previous_end = -1
    for m in _CITED.finditer(text):
        start = m.start()
        if start > 0 and (text[start - 1].isalnum() or text[start - 1] in "_:"):
            continue  # part of a longer word
        out.append(text[last:start])
        between = text[previous_end:start] if previous_end >= 0 else None
        number = f"({EQUATIONS[m.group(2)]})"
        if m.group(1):
            out.append(m.group(1) + number)
        elif between is not None and _LIST.fullmatch(between):
            out.append(number)
        else:
            out.append("Eq. " + number)
        last = previous_end = m.end()
    out.append(text[last:])
    return "".join(out)
