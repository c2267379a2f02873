"""LaTeX rendering of result rows: a booktabs table per paper table (``posecrb tables --format latex``)."""
from __future__ import annotations

import math


def tex_number(v: object) -> str:
    """One LaTeX table cell: ``--`` for None, yes/no, integers as is, floats as ``$m\\times10^{e}$``
    (4 decimals, the mantissa renormalised when it rounds to 10), text with ``_ % &`` escaped."""
    if v is None:
        return "--"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if v == 0 or not math.isfinite(v):
            return str(v)
        e = int(math.floor(math.log10(abs(v))))
        m = v / 10 ** e
        if f"{m:.4f}".startswith("10."):
            m, e = m / 10, e + 1
        return f"${m:.4f}\\times10^{{{e}}}$"
    return str(v).replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")


def to_latex(rows: list[dict], columns: list[str], caption: str, headers: dict[str, str]) -> str:
    """A booktabs ``table`` environment: one column per ``columns`` (headers from ``headers``), one
    line per row, ``caption`` escaped like a cell."""
    def head(c: str) -> str:
        return tex_number(headers.get(c, c)).replace("λ∞", r"$\lambda_\infty$")

    lines = [r"\begin{table}[t]", r"\centering", f"\\caption{{{tex_number(caption)}}}",
             r"\begin{tabular}{" + "l" + "r" * (len(columns) - 1) + "}", r"\toprule",
             " & ".join(head(c) for c in columns) + r" \\", r"\midrule"]
    lines += [" & ".join(tex_number(r.get(c)) for c in columns) + r" \\" for r in rows]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"
