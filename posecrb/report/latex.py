"""LaTeX rendering of result rows: a booktabs table per paper table (``posecrb tables --format latex``)."""
from __future__ import annotations

import math


def tex_number(v: object) -> str:
    """One LaTeX table cell: ``--`` for None, yes/no, integers as is, floats as ``$m\\times10^{e}$``
    (4 decimals, the mantissa renormalised when it rounds to 10), text escaped (``tex_escape``)."""
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
    return tex_escape(str(v))


_TEX_SPECIAL = {"\\": r"\textbackslash{}", "{": r"\{", "}": r"\}", "$": r"\$", "#": r"\#", "%": r"\%",
                "&": r"\&", "_": r"\_", "^": r"\textasciicircum{}", "~": r"\textasciitilde{}",
                "<": r"\textless{}", ">": r"\textgreater{}", "|": r"\textbar{}"}


def tex_escape(text: str) -> str:
    """``text`` as literal LaTeX (every character with a meaning to LaTeX escaped, line breaks as
    spaces): a dataset named ``a_b&c$`` or ``\\input{x}`` is printed as written, never executed."""
    return "".join(_TEX_SPECIAL.get(ch, ch) for ch in " ".join(str(text).splitlines()))


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
