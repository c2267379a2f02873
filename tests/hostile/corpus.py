"""A corpus of hostile pose-graph inputs, generated (a few hundred bytes each).

Every case is a pair of texts: ``text``, the hostile file, and either ``clean``, the SAME
graph written plainly (the hostile file must give the same numbers), or an expected
rejection ``(line, reason)`` (exit 1 with ``file:line`` and the reason).

The base graphs are tiny noisy loops with a loop closure (2D: 5 poses, 6 edges; 3D: 4
poses, 5 edges) so that every command, the certified solve included, runs in milliseconds.
"""
from __future__ import annotations

from dataclasses import dataclass

# Line separators of str.splitlines that are NOT line ends in g2o/TORO (and must not split
# a comment): form feed, vertical tab, file/group/record separators, NEL, U+2028, U+2029.
ODD_SEPARATORS = {"ff": "\f", "vt": "\v", "fs": "\x1c", "gs": "\x1d", "rs": "\x1e", "nel": "\x85",
                  "ls": "\u2028", "ps": "\u2029"}

INFO2 = "500 0 0 500 0 1000"
BIG_IDS = (5, 2 ** 53, 2 ** 53 + 1, 2 ** 62 + 7, 2 ** 63 - 1)   # increasing, like 0..4
INFO3 = "400 0 0 0 0 0 400 0 0 0 0 400 0 0 0 900 0 0 900 0 900"


def _edges2(ids=(0, 1, 2, 3, 4)) -> list[str]:
    a, b, c, d, e = ids
    return [f"EDGE_SE2 {a} {b} 1.02 0.01 0.01 {INFO2}",
            f"EDGE_SE2 {b} {c} 0.98 -0.02 1.58 {INFO2}",
            f"EDGE_SE2 {c} {d} 1.01 0.03 1.55 {INFO2}",
            f"EDGE_SE2 {d} {e} 0.99 0.01 1.57 {INFO2}",
            f"EDGE_SE2 {e} {a} 0.03 1.01 1.59 {INFO2}",
            f"EDGE_SE2 {b} {d} 0.02 1.40 3.12 {INFO2}"]


def _vertices2(ids=(0, 1, 2, 3, 4)) -> list[str]:
    xy = [(0, 0, 0), (1, 0, 0), (1, 1, 1.57), (0, 1, 3.14), (0, 0, -1.57)]
    return [f"VERTEX_SE2 {i} {x} {y} {t}" for i, (x, y, t) in zip(ids, xy)]


def graph2(ids=(0, 1, 2, 3, 4), vertices: bool = True) -> list[str]:
    return (_vertices2(ids) if vertices else []) + _edges2(ids)


Q_HALF = "0 0 0.70710678118654752 0.70710678118654752"   # 90 degrees about z, normalised


def graph3(q_closure: str = Q_HALF) -> list[str]:
    return ["VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1",
            "VERTEX_SE3:QUAT 1 1 0 0 0 0 0.7071 0.7071",
            "VERTEX_SE3:QUAT 2 1 1 0 0 0 1 0",
            "VERTEX_SE3:QUAT 3 0 1 0 0 0 -0.7071 0.7071",
            f"EDGE_SE3:QUAT 0 1 1.01 0.02 0.01 0 0 0.7072 0.7070 {INFO3}",
            f"EDGE_SE3:QUAT 1 2 0.99 -0.01 0.02 0.01 0 0.7069 0.7073 {INFO3}",
            f"EDGE_SE3:QUAT 2 3 1.02 0.01 -0.01 0 0.01 0.7070 0.7072 {INFO3}",
            f"EDGE_SE3:QUAT 3 0 0.98 0.02 0.00 {q_closure} {INFO3}",
            f"EDGE_SE3:QUAT 0 2 1.01 0.99 0.01 0 0 0.9999 0.0100 {INFO3}"]


def text(lines: list[str], end: str = "\n") -> str:
    return end.join(lines) + end


@dataclass(frozen=True)
class Case:
    name: str
    text: str | bytes
    clean: str | None = None          # same graph written plainly (accepted cases)
    line: int | None = None           # expected error line (rejected cases)
    reason: str | None = None         # expected substring of the error
    dim: int = 2

    @property
    def accepted(self) -> bool:
        return self.clean is not None


def _with_line(lines: list[str], k: int, new: str) -> list[str]:
    out = list(lines)
    out[k] = new
    return out


def cases() -> list[Case]:
    g2 = graph2()
    clean2 = text(g2)
    out: list[Case] = []

    # -- line structure: odd separators inside comments stay comments; line numbers stay right
    odd = "".join(f"# {name}:{ch}EDGE_SE2 0 2 5 5 1 {INFO2}\n" for name, ch in ODD_SEPARATORS.items())
    out.append(Case("odd_separators_in_comments", odd + clean2, clean=clean2))
    bad_after = g2 + [f"EDGE_SE2 1 3 1 0 0 {INFO2} 7"]
    out.append(Case("line_numbers_after_odd_separators", odd + text(bad_after),
                    line=len(ODD_SEPARATORS) + len(bad_after), reason="needs 11 numeric fields"))
    out.append(Case("crlf_line_ends", text(g2, "\r\n"), clean=clean2))
    out.append(Case("cr_line_ends", text(g2, "\r"), clean=clean2))
    out.append(Case("odd_separator_inside_data", text(_with_line(g2, 6, g2[6].replace(" 0.98 ", " 0.98\x1c"))),
                    line=7, reason="needs 11 numeric fields, found 10"))   # \x1c is not a field separator

    # -- ids: integers, never through float64
    # 2^53 and 2^53 + 1 are the same float64 (a false self-loop when read through floats)
    out.append(Case("ids_beyond_2p53", text(graph2(BIG_IDS)), clean=clean2))   # same order of ids
    overflow = _with_line(g2, 5, g2[5].replace("EDGE_SE2 0 1", f"EDGE_SE2 {2 ** 63} 1"))
    out.append(Case("id_overflows_int64", text(overflow),
                    line=6, reason="is not a non-negative integer id"))
    for name, tok in (("id_negative", "-1"), ("id_fractional", "1.0"), ("id_exponent", "1e0"),
                      ("id_underscore", "1_0"), ("id_plus", "+1")):
        out.append(Case(name, text(_with_line(g2, 6, g2[6].replace("EDGE_SE2 1 2", f"EDGE_SE2 {tok} 2"))),
                        line=7, reason="is not a non-negative integer id"))
    # -- numbers: Python's float() extensions are not numbers here
    out.append(Case("value_underscore", text(_with_line(g2, 7, g2[7].replace(" 1.01 ", " 1_01 "))),
                    line=8, reason="'1_01' is not a number"))
    out.append(Case("value_unicode_digit", text(_with_line(g2, 7, g2[7].replace(" 1.01 ", " \u0661.01 "))),
                    line=8, reason="is not a number"))
    out.append(Case("value_nan", text(_with_line(g2, 8, g2[8].replace(" 0.99 ", " nan "))),
                    line=9, reason="non-finite"))
    out.append(Case("value_inf", text(_with_line(g2, 8, g2[8].replace(" 0.99 ", " -Infinity "))),
                    line=9, reason="non-finite"))

    # -- magnitudes that would overflow downstream: rejected at parse time
    big_info = "1e200 0 0 1e200 0 1e200"
    out.append(Case("information_1e200", text(_with_line(g2, 9, g2[9].replace(INFO2, big_info))),
                    line=10, reason="information entry 1e+200 exceeds"))
    out.append(Case("information_1e308", text(_with_line(g2, 9, g2[9].replace(INFO2, "1e308 0 0 1e308 0 1e308"))),
                    line=10, reason="information entry 1e+308 exceeds"))
    out.append(Case("information_1e-200", text(_with_line(g2, 9, g2[9].replace(INFO2, "1e-200 0 0 1e-200 0 1"))),
                    line=10, reason="translation precision tau = 0 is outside"))   # a c - b^2 underflows
    out.append(Case("translation_1e308", text(_with_line(g2, 10, g2[10].replace(" 0.02 1.40 ", " 1e308 1.40 "))),
                    line=11, reason="translation component 1e+308 exceeds"))
    out.append(Case("vertex_translation_1e308", text(_with_line(g2, 2, "VERTEX_SE2 2 1e308 1 1.57")),
                    line=3, reason="translation component 1e+308 exceeds"))

    # -- information matrices: scale-aware positive definiteness
    wide = "1e12 0 0 1e-3 0 1000"
    out.append(Case("information_diag_1e12_1e-3", text([ln.replace(INFO2, wide) for ln in g2]),
                    clean=text([ln.replace(INFO2, "1000000000000 0 0 0.001 0 1000") for ln in g2])))
    out.append(Case("information_not_pd", text(_with_line(g2, 6, g2[6].replace(INFO2, "1 2 0 1 0 5"))),
                    line=7, reason="translation block of the information matrix is not positive definite"))
    out.append(Case("information_negative_diagonal", text(_with_line(g2, 6, g2[6].replace(INFO2, "-1 0 0 1 0 5"))),
                    line=7, reason="diagonal entry 1 is -1"))

    # -- 3D quaternions: normalised safely (scaled first), never read as the identity
    g3 = graph3()
    clean3 = text(g3)
    out.append(Case("quaternion_norm_overflows", text(graph3("0 0 1e308 1e308")), clean=clean3, dim=3))
    out.append(Case("quaternion_norm_underflows", text(graph3("0 0 1e-320 1e-320")), clean=clean3, dim=3))
    out.append(Case("quaternion_zero", text(graph3("0 0 0 0")), line=8, reason="zero quaternion", dim=3))
    tiny_kappa = "400 0 0 0 0 0 400 0 0 0 0 400 0 0 0 1e-60 0 0 1e-60 0 1e-60"
    out.append(Case("rotation_information_1e-60_3d", text(_with_line(g3, 5, g3[5].replace(INFO3, tiny_kappa))),
                    line=6, reason="rotation weight omega(kappa)/3 (eq. 59)", dim=3))

    # -- not text, nothing to read
    out.append(Case("invalid_utf8", clean2.encode() + b"# \xff\xfe\n", line=len(g2) + 1, reason="not a text file"))
    out.append(Case("comments_only", "# nothing\n\f\n", reason="no pose-graph edges"))
    return out


CASES = {c.name: c for c in cases()}


def write(case: Case, directory, name: str | None = None):
    """Write ``case`` (hostile) into ``directory``; returns the path."""
    path = directory / (name or f"{case.name}.g2o")
    if isinstance(case.text, bytes):
        path.write_bytes(case.text)
    else:
        path.write_bytes(case.text.encode("utf-8"))   # no newline translation
    return path


def write_clean(case: Case, directory):
    path = directory / f"{case.name}.clean.g2o"
    path.write_bytes(case.clean.encode("utf-8"))
    return path


__all__ = ["CASES", "Case", "ODD_SEPARATORS", "cases", "graph2", "graph3", "text", "write", "write_clean"]
