"""`posecrb tables`: formats parse back, statuses, run record, paper comparison."""
import csv
import hashlib
import io
import json
import re
from decimal import Decimal

import pytest

from posecrb.cli import main
from posecrb.core.errors import ArgumentError
from posecrb.evaluation.published import PAPER_NAME, TABLE_II
from posecrb.evaluation.tables import HEADERS, TableSettings, failed, published_settings, table_rows
from posecrb.report.latex import tex_number as _tex_number

from ..numerics import EPS

SUBSET = ["--datasets", "CSAIL", "--datasets", "tinyGrid3D"]


def _run(capfd, *args):
    rc = main(["tables", *SUBSET, "--repeat", "1", *args])
    out, err = capfd.readouterr()
    return rc, out, err


def test_json_and_csv_parse_back(shared_datasets, capfd):
    rc, out, _ = _run(capfd, "--format", "json")
    assert rc == 0
    data = json.loads(out)
    rows = {r["dataset"]: r for r in data["rows"]}
    assert rows["CSAIL"]["poses"] == 1045 and rows["tinyGrid3D"]["dim"] == 3
    assert rows["CSAIL"]["lb"] < rows["CSAIL"]["fim_logdet"] < rows["CSAIL"]["ub"]
    assert [r["dataset"] for r in data["tables"]["I"]] == ["CSAIL"]
    assert [r["dataset"] for r in data["tables"]["IV"]] == ["tinyGrid3D"]
    rc, out, _ = _run(capfd, "--format", "csv")
    parsed = list(csv.DictReader(io.StringIO(out)))
    assert [r["dataset"] for r in parsed] == ["CSAIL", "tinyGrid3D"]
    assert float(parsed[0]["lb"]) == rows["CSAIL"]["lb"]   # repr round-trips exactly
    assert {r["fim_variant"] for r in parsed} == {"consistent"}


def _printed(cell: str) -> tuple[float, float]:
    """A number as printed (plain, 1.2345e-04 or LaTeX $1.2345\\times10^{-4}$) and half a unit of its
    last printed digit: the rendering's rounding error bound."""
    m = re.fullmatch(r"\$([-+0-9.]+)\\times10\^\{([-+0-9]+)\}\$", cell)
    text = f"{m.group(1)}E{m.group(2)}" if m else cell
    return float(text), 0.5 * 10.0 ** Decimal(text).as_tuple().exponent


def _assert_cells_match(cells: list[str], row: dict, columns: list[str]):
    """Each printed cell is the computed value: strings and integers exactly, floats to the
    rounding of the printed digits (with the last bit of the value itself)."""
    assert len(cells) == len(columns)
    for cell, c in zip(cells, columns):
        v = row[c]
        if v is None:
            assert cell in ("-", "--"), (c, cell)
        elif isinstance(v, float):
            got, half_unit = _printed(cell)
            assert abs(got - v) <= half_unit + EPS * abs(v), (c, cell, v)
        else:
            assert cell == str(v), (c, cell, v)


def _markdown_tables(text: str) -> list[list[list[str]]]:
    """Every markdown table of ``text`` as rows of cells (header first, the rule dropped)."""
    out = []
    for block in (b for b in text.split("### ") if b.strip()):
        lines = [ln for ln in block.splitlines() if ln.startswith("|")]
        assert set(lines[1]) <= set("|-")
        out.append([[re.sub(r"\\(.)", r"\1", c.strip()) for c in re.split(r"(?<!\\)\|", ln.strip()[1:-1])]
                    for i, ln in enumerate(lines) if i != 1])     # cells split at unescaped |, unescaped
    return out


def _latex_tabular(text: str) -> tuple[str, list[list[str]]]:
    """(column spec, rows of cells with the header first) of the one tabular in ``text``."""
    assert text.count(r"\begin{tabular}") == 1
    spec = re.search(r"\\begin\{tabular\}\{([lrc]+)\}", text).group(1)
    body = text.split(r"\toprule")[1].split(r"\bottomrule")[0].replace(r"\midrule", "")
    rows = [ln.strip() for ln in body.splitlines() if ln.strip()]
    assert all(ln.endswith(r"\\") for ln in rows)
    return spec, [[_tex_unescape(c.strip()) for c in ln[:-2].split(" & ")] for ln in rows]


def _tex_unescape(cell: str) -> str:
    """The text a LaTeX cell prints (the escapes of posecrb.report.latex.tex_escape undone)."""
    for tex, ch in ((r"\textbackslash{}", "\\"), (r"\textasciicircum{}", "^"), (r"\textasciitilde{}", "~"),
                    (r"\textless{}", "<"), (r"\textgreater{}", ">"), (r"\textbar{}", "|")):
        cell = cell.replace(tex, ch)
    return re.sub(r"\\([{}$#%&_])", r"\1", cell)


def test_markdown_cells_are_the_computed_rows(shared_datasets, capfd, tmp_path):
    rc, out, _ = _run(capfd, "--format", "markdown", "--table", "1", "--table", "3", "--out", str(tmp_path))
    assert rc == 0
    tables = _markdown_tables(out)
    assert len(tables) == 2
    for t, cells in zip((1, 3), tables):
        rows = json.loads((tmp_path / f"table{t}.json").read_text())   # the same run's values
        columns = list(rows[0])
        assert cells[0] == [HEADERS.get(c, c) for c in columns]
        assert [r[0] for r in cells[1:]] == [r["dataset"] for r in rows] == ["CSAIL"]
        for printed, row in zip(cells[1:], rows):
            _assert_cells_match(printed, row, columns)


def test_latex_cells_are_the_computed_rows(shared_datasets, capfd, tmp_path):
    rc, out, _ = _run(capfd, "--format", "latex", "--table", "2", "--out", str(tmp_path))
    assert rc == 0
    rows = json.loads((tmp_path / "table2.json").read_text())
    columns = list(rows[0])
    spec, cells = _latex_tabular(out)
    assert spec == "l" + "r" * (len(columns) - 1)
    assert len(cells[0]) == len(columns) and cells[0][:3] == ["dataset", "# Poses", "# Meas."]
    assert [r[0] for r in cells[1:]] == [r["dataset"] for r in rows] == ["tinyGrid3D"]
    for printed, row in zip(cells[1:], rows):
        _assert_cells_match(printed, row, columns)
    # the derived columns, recomputed from the row's own bounds
    row = rows[0]
    assert row["gap_ub_rel"] == pytest.approx((row["ub"] - row["lb"]) / row["lb"], rel=4 * EPS)
    assert row["gap_fim_rel"] == pytest.approx((row["fim_logdet"] - row["lb"]) / row["lb"], rel=4 * EPS)
    assert "(59)" in out.split(r"\begin{tabular}")[0]   # the Table II footnote is in the caption
    assert _latex_tabular((tmp_path / "table2.tex").read_text())[1] == cells   # the file: the same table


def test_compare_paper_and_table2_fit_labelled(shared_datasets, capfd):
    rc, out, _ = _run(capfd, "--format", "json", "--compare-paper", "--rotation-weight", "table2")
    data = json.loads(out)
    csail = data["tables"]["I"][0]
    printed = 1.9860e4   # the paper's Table I, CSAIL, FIM log-det
    assert csail["paper_fim_logdet"] == printed
    assert csail["rel_diff_fim_logdet"] == pytest.approx((csail["fim_logdet"] - printed) / printed, rel=4 * EPS)
    # FIM at the certified optimum: the printed value to its rounding (+-0.5) plus a margin of 4
    assert abs(csail["fim_logdet"] - printed) < 4 * 0.5
    tiny = data["tables"]["II"][0]
    printed = 2.4163e2   # Table II, tiny-grid, lb
    assert tiny["paper_lb"] == printed
    assert tiny["rel_diff_lb"] == pytest.approx((tiny["lb"] - printed) / printed, rel=4 * EPS)
    # the empirical fit reproduces Table II's lb; the fit's factor 0.5515 has 4 digits (+-5e-5 relative)
    assert abs(tiny["rel_diff_lb"]) < 1e-3
    rc, out, _ = _run(capfd, "--format", "markdown", "--table", "2", "--rotation-weight", "table2")
    assert "EMPIRICAL" in out


def test_out_dir_has_every_format_and_run_record(shared_datasets, capfd, tmp_path):
    rc, out, _ = _run(capfd, "--format", "csv", "--out", str(tmp_path))
    assert rc == 0
    rows = {r["dataset"]: r for r in json.loads((tmp_path / "rows.json").read_text())}
    rows_csv = (tmp_path / "rows.csv").read_text()
    assert list(csv.DictReader(io.StringIO(out))) == list(csv.DictReader(io.StringIO(rows_csv)))
    for t in (1, 2, 3, 4):
        trs = json.loads((tmp_path / f"table{t}.json").read_text())
        assert [r["dataset"] for r in trs] == (["CSAIL"] if t in (1, 3) else ["tinyGrid3D"])
        parsed = list(csv.DictReader(io.StringIO((tmp_path / f"table{t}.csv").read_text())))
        assert [list(r) for r in parsed] == [list(r) for r in trs]
        for p, r in zip(parsed, trs):   # csv holds repr(): floats round-trip exactly
            assert {k: type(r[k])(p[k]) if r[k] is not None else None for k in r} == r
        md = _markdown_tables("### \n" + (tmp_path / f"table{t}.md").read_text())[0]
        for printed, r in zip(md[1:], trs):
            _assert_cells_match(printed, r, list(r))
        for printed, r in zip(_latex_tabular((tmp_path / f"table{t}.tex").read_text())[1][1:], trs):
            _assert_cells_match(printed, r, list(r))
    run = json.loads((tmp_path / "run.json").read_text())
    for name, file in (("CSAIL", "CSAIL.g2o"), ("tinyGrid3D", "tinyGrid3D.g2o")):
        path = shared_datasets / file
        assert run["datasets"][name] == {"path": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
                                         "status": "ok"}
        assert rows[name]["sha256"] == run["datasets"][name]["sha256"]
    assert run["settings"] == {"repeat": 1, "rotation_weight": "eq59", "data_dir": None, "solver": {},
                               "fim_variant": "consistent", "ordering": "auto"}
    import numpy

    assert run["versions"]["numpy"] == numpy.__version__
    assert TableSettings.from_record(run["settings"]) == TableSettings(repeat=1)


def test_run_records_before_the_rename_still_read():
    """run.json of 0.2 names the rotation weight rotation_model: read as rotation_weight, with a warning."""
    old = {"repeat": 1, "rotation_model": "table2", "data_dir": None, "solver": {}, "fim_variant": "eq64",
           "ordering": "auto"}
    with pytest.warns(DeprecationWarning, match="rotation_weight"):
        settings = TableSettings.from_record(old)
    assert settings.rotation_weight == "table2" and settings.as_published
    with pytest.raises(ArgumentError, match="unknown keys"):
        TableSettings.from_record({"rotation_wieght": "eq59"})
    with pytest.raises(ArgumentError):
        TableSettings.from_record(["eq59"])


def test_requested_missing_dataset_is_a_row_and_exit_one(shared_datasets, capfd):
    rc = main(["tables", "--datasets", "CSAIL", "--datasets", "nosuchdataset", "--repeat", "1", "--format", "json"])
    out, err = capfd.readouterr()
    assert rc == 1
    rows = {r["dataset"]: r for r in json.loads(out)["rows"]}
    assert rows["nosuchdataset"]["status"] == "not found"
    assert "posecrb datasets fetch nosuchdataset" in rows["nosuchdataset"]["hint"]
    assert rows["CSAIL"]["status"] == "ok"


def test_failed_rows_policy():
    rows = [{"dataset": "a", "status": "ok"}, {"dataset": "grid3D", "status": "not found"},
            {"dataset": "b", "status": "not positive definite"}, {"dataset": "c", "status": "uncertified"}]
    assert [r["dataset"] for r in failed(rows, None)] == ["b", "c"]
    assert [r["dataset"] for r in failed(rows, ["grid3D"])] == ["grid3D", "b", "c"]


def test_views_split_by_dimension():
    rows = [{"dataset": "CSAIL", "dim": 2, "status": "ok", "fim_build_time": 2.0, "laplacians_build_time": 0.5},
            {"dataset": "sphere2500", "dim": 3, "status": "ok"}]
    t1, cols = table_rows(rows, 1)
    t3, _ = table_rows(rows, 3)
    assert [r["dataset"] for r in t1] == ["CSAIL"] and "fim_logdet" in cols
    assert t3[0]["build_ratio"] == 4.0


def test_tex_number():
    assert _tex_number(19860.0) == r"$1.9860\times10^{4}$"
    assert _tex_number(9.99996e-3) == r"$1.0000\times10^{-2}$"
    assert _tex_number(None) == "--" and _tex_number("a_b") == r"a\_b"


def _printed_digits_agree(value: float, printed: float, digits: int = 5) -> bool:
    """``value`` rounded to the printed significant digits is within one unit of the last digit."""
    import math

    unit = 10.0 ** (math.floor(math.log10(abs(printed))) - (digits - 1))
    return abs(round(value / unit) - round(printed / unit)) <= 1


@pytest.mark.slow
def test_as_published_reproduces_table_two_fim_and_lb(shared_datasets):
    """`posecrb tables --as-published`: eq. (64) as printed with w = 0.5515 kappa^2 gives the printed
    FIM and lb columns of Table II to one unit of the last printed digit on every 3D dataset of the
    paper that is available (grid3D and rim are not in the shared folder)."""
    from posecrb.evaluation.tables import dataset_row

    settings = published_settings(repeat=1, data_dir=str(shared_datasets))
    checked = 0
    for name in ("tinyGrid3D", "smallGrid3D", "parking-garage", "sphere2500", "torus3D", "cubicle"):
        row = dataset_row(name, settings)
        assert row["status"] == "ok", row
        assert row["fim_variant"] == "eq64" and row["rotation_weight"] == "table2"
        printed = TABLE_II[PAPER_NAME[name]]
        assert _printed_digits_agree(row["fim_logdet"], printed[2]), (name, row["fim_logdet"], printed[2])
        assert _printed_digits_agree(row["lb"], printed[6]), (name, row["lb"], printed[6])
        checked += 1
    assert checked == 6


def test_default_table_two_is_the_model_and_says_so_once(shared_datasets, capfd):
    rc, out, _ = _run(capfd, "--format", "markdown", "--table", "2", "--table", "4")
    assert rc == 0
    assert out.count("differ from the printed Table II by design") == 1 and "--as-published" in out
    assert "| consistent |" in out
    rc, out, _ = _run(capfd, "--format", "markdown", "--table", "2", "--as-published")
    assert rc == 0 and "Table II as published" in out and "| eq64 |" in out
    rc, out, _ = _run(capfd, "--format", "json", "--table", "1", "--as-published")
    rows = {r["dataset"]: r for r in json.loads(out)["rows"]}
    assert rows["CSAIL"]["fim_variant"] == "eq64"     # 2D: the same matrix, labelled as computed
    assert main(["tables", "--datasets", "CSAIL", "--as-published", "--rotation-weight", "eq59"]) == 2


def test_tables_without_rows_are_not_printed_and_the_note_once(shared_datasets, capfd):
    rc, out, _ = _run(capfd, "--format", "markdown")
    assert rc == 0
    assert [b.splitlines()[0] for b in out.split("### ") if b.strip()] == [
        "Table I: metric results, 2D datasets", "Table II: metric results, 3D datasets",
        "Table III: matrix construction time, 2D datasets", "Table IV: matrix construction time, 3D datasets"]
    assert out.count("differ from the printed Table II by design") == 1   # Table II's note, not under IV
    rc, out, _ = _run(capfd)                                        # the terminal table
    assert " ".join(out.split()).count("differ from the printed Table II by design") == 1 and "Table IV" in out
    rc = main(["tables", "--datasets", "CSAIL", "--repeat", "1", "--format", "markdown"])
    out, err = capfd.readouterr()
    assert rc == 0 and "Table I:" in out and "Table III:" in out
    assert "Table II:" not in out and "Table IV:" not in out and "kappa" not in out
    rc = main(["tables", "--datasets", "CSAIL", "--repeat", "1", "--table", "2"])
    out, err = capfd.readouterr()
    assert rc == 0 and out == "" and "Table II: no 3D dataset, not printed" in err


def test_first_run_without_any_dataset_uses_the_builtin_graph(tmp_path, monkeypatch, capfd):
    """A stock machine: nothing on the search path. One warning, only the 2D tables (it is 2D)."""
    monkeypatch.setattr("posecrb.datasets.search.search_path", lambda data_dir=None: [tmp_path / "nothing"])
    rc = main(["tables", "--all", "--repeat", "1"])
    out, err = capfd.readouterr()
    assert rc == 0
    assert err.count("built-in synthetic graph") == 1 and err.count("warning") == 1
    assert "builtin_demo" in out and "Table I:" in out and "Table III:" in out
    assert "Table II:" not in out and "Table IV:" not in out


@pytest.mark.parametrize("ext", ["png", "svg"])
def test_plot_writes_one_figure_atomically(shared_datasets, capfd, tmp_path, ext):
    target = tmp_path / "fig" / f"tables.{ext}"
    target.parent.mkdir()         # an output's directory must exist (tests/files/test_output_options.py)
    rc, _, _ = _run(capfd, "--format", "csv", "--plot", str(target))
    assert rc == 0
    data = target.read_bytes()
    if ext == "png":
        assert data.startswith(b"\x89PNG\r\n\x1a\n")
    else:
        text = data.decode()
        assert text.lstrip().startswith("<?xml") and "<svg" in text and text.rstrip().endswith("</svg>")
        assert "CSAIL" in text and "tinyGrid3D" in text                # text stays text in the SVG
    assert sorted(p.name for p in target.parent.iterdir()) == [target.name]   # no temporary file left


def test_plot_target_is_checked_before_the_work(tmp_path, capfd):
    # exit 2 (usage), not 1 (the dataset does not exist): nothing was computed
    for bad in (tmp_path / "t.eps", tmp_path / "t", tmp_path):
        assert main(["tables", "--datasets", "nosuchdataset", "--plot", str(bad)]) == 2
    (tmp_path / "file").write_text("")
    assert main(["tables", "--datasets", "nosuchdataset", "--plot", str(tmp_path / "file" / "t.png")]) == 2
    err = capfd.readouterr().err
    assert ".eps" in err and "not a directory" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_plot_tables_values(tmp_path):
    """The figure's numbers: (x - lb)/lb and our/paper time ratios, read back from the SVG's data."""
    from posecrb.report.plots import plot_tables

    rows = [{"dataset": "CSAIL", "dim": 2, "status": "ok", "lb": 100.0, "fim_logdet": 101.0, "ub": 110.0,
             "fim_time": 2.3284e-3, "lb_time": 3.6712e-3 / 2},
            {"dataset": "mine", "dim": 3, "status": "ok", "lb": 10.0, "fim_logdet": 10.5, "ub": 12.0},
            {"dataset": "grid3D", "status": "not found"}]
    import matplotlib.pyplot as plt

    captured = {}
    orig = plt.Axes.scatter

    def spy(ax, x, y, *a, **kw):
        captured.setdefault(kw.get("label"), []).append((list(x), list(y)))
        return orig(ax, x, y, *a, **kw)

    plt.Axes.scatter = spy
    try:
        plot_tables(rows, tmp_path / "t.png")
    finally:
        plt.Axes.scatter = orig
    (fx, fy), = captured["FIM log-det\n(certified optimum)"]
    (ux, uy), = captured["upper bound ub (eq. 75)"]
    assert fx == [0, 1] and fy == pytest.approx([0.01, 0.05]) and uy == pytest.approx([0.1, 0.2])
    (tx, ty), = captured["FIM log-det (Table I/II)"]
    assert ty == pytest.approx([1.0])                             # same time as printed -> 1
    (tx, ty), = captured["lb (Table I/II)"]
    assert ty == pytest.approx([0.5])
    with pytest.raises(ValueError):
        plot_tables([{"dataset": "grid3D", "status": "not found"}], tmp_path / "u.png")
    assert not (tmp_path / "u.png").exists()
