"""mkdocs hook: the generated pages of the documentation site.

At ``mkdocs build`` this adds, without writing into ``docs/``:

* ``catalogue.md``: one entry per registry family (``ccjax.estimators.registry.available()``),
  with its measured speed and accuracy from ``docs/data/catalogue.json``;
* ``thesis/index.md``, ``thesis/table-T.md`` and their figures: each reproduced thesis table
  (``docs/data/reproduce-T.json``, the output of ``ccjax reproduce T --json``), ours beside the
  thesis with the difference and the sampling error;
* ``thesis/figures.md``: error against the number of surfaces and Fig. 10.1
  (``docs/data/compare-barnard1999.json``, from ``ccjax compare --json``) and the Fig. 4.1-style
  chromaticities of the thesis world (``docs/data/world-barnard1999.json``);
* ``cli.md``: the help of every command, from ``ccjax.cli.build_parser()``.

Every number comes from the committed JSON files, which ``docs/scripts/generate_data.py``
regenerates; nothing is typed by hand. The functions are importable (tests/test_docs.py).
"""

from __future__ import annotations

import argparse
import html
import io
import json
import os
import pathlib
import re

DOCS = pathlib.Path(__file__).resolve().parent
DATA = DOCS / "data"
TABLES = ("4.2", "4.3", "4.4", "5.1", "6.1", "10.1", "10.2")
TABLE_TITLES = {
    "4.2": "synthetic scenes of 8 matte surfaces (§4.7)",
    "4.3": "8 surfaces with specularities (§4.7)",
    "4.4": "specular scenes with clipping at 400, 300 and 250 (§4.7)",
    "5.1": "sensor sharpening, Sony DXC-930, 8 surfaces (§5.7)",
    "6.1": "the new gamut-mapping methods at 4, 8 and 16 surfaces (§6.3)",
    "10.1": "3-D Colour by Correlation, matte and specular (§10.3)",
    "10.2": "3-D Colour by Correlation, 8 matte surfaces (§10.3)",
}
FIG_10_1 = ("CRULE-MV", "ND-ECRULE-SCWIA-12", "C-by-C-MAP", "C-by-C-MMSE", "RGB-C-by-C-MAP", "RGB-C-by-C-MMSE")


def _load(name: str) -> dict | None:
    path = DATA / name
    return json.loads(path.read_text()) if path.is_file() else None


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    # No timestamp or software metadata: the same data give the same bytes.
    fig.savefig(buffer, format="png", dpi=100, metadata={"Software": None})
    _pyplot().close(fig)
    return buffer.getvalue()


def _cell(value, spec: str = ".4g") -> str:
    return "–" if value is None else format(value, spec)


def _code(text: str) -> str:
    return "`" + text.replace("`", "'") + "`"


def _escape(text: str) -> str:
    # Registry descriptions are plain text: no links, HTML or emphasis from their brackets.
    for char in "\\[]*_":
        text = text.replace(char, "\\" + char)
    return text.replace("<", "&lt;")


def _cell_code(text: str) -> str:
    # In a table cell a pipe separates columns even inside a code span (and a backslash before it
    # stays visible there): write the code as HTML with the pipe as a character reference.
    # Markdown still reads inline HTML's content: brackets become character references too, or
    # ``[FL-][STD-|SPEC-]`` is taken for a reference link.
    escaped = html.escape(text).replace("|", "&#124;<wbr>").replace("[", "&#91;").replace("]", "&#93;<wbr>")
    # The cell's code never wraps by itself (docs/stylesheets/extra.css); it may break after a
    # choice, an optional part or a group, not inside a token.
    return "<code>" + escaped.replace(")", ")<wbr>") + "</code>"


# -- the estimator catalogue ---------------------------------------------------------------------

INPUTS = {"surfaces": "surface lists `rgb (P, 3)`, `mask (P,)`", "image": "images `(H, W, 3)`, `mask (H, W)`"}
_SECTION = re.compile(r"(§\s?[0-9.]+[0-9]|ch\.\s?[0-9]+)")


def thesis_section(description: str) -> str:
    """The thesis section a registry description cites (``§4.5.1``, ``ch. 10``), or ``–``."""
    found = _SECTION.findall(description)
    return ", ".join(found) if found else "– (not in the thesis)"


def catalogue_markdown(entries=None, measured: dict | None = None) -> str:
    """The catalogue page: one ``##`` entry per registry family.

    Arguments:
        entries: registry entries (default ``ccjax.estimators.registry.available()``).
        measured: ``docs/data/catalogue.json`` (default: read it).

    Returns:
        The page's markdown.
    """
    if entries is None:
        from ccjax.estimators import registry

        entries = registry.available()
    if measured is None:
        measured = _load("catalogue.json") or {"families": []}
    by_grammar = {family["grammar"]: family for family in measured.get("families", [])}
    lines = [
        "# Estimator catalogue",
        "",
        f"Every family of labels the registry knows ({len(entries)} families; `ccjax methods` lists the same).",
        "A label names a fitted estimator: `ccjax.fit(label, world)`. Speeds are scenes per second of the",
        "compiled, batched estimator (`ccjax.estimate_batch` under `jax.jit`, median of 3 warm runs on batches of "
        + ", ".join(f"{b} scenes at {n} surfaces" for n, b in measured.get("speed_batch", {}).items())
        + f"); accuracy is the RMS (r,g) error over {measured.get('n_scenes', '–')} scenes of the thesis world"
        " (`World.barnard1999`), ± its sampling error (the standard error over scenes).",
        "",
        f"Measured on: {measured.get('machine', '–')}. Regenerate with `python docs/scripts/generate_data.py "
        "--only catalogue` ([documentation data](data.md)).",
        "",
        "| family | thesis | input | differentiable | rg RMS at 8 | at 64 | scenes/s at 8 | at 64 |",
        "| --- | --- | --- | --- | ---: | ---: | ---: | ---: |",
    ]
    details = []
    for entry in entries:
        family = by_grammar.get(entry.grammar, {})
        rms = family.get("rg_rms", {})
        speed = family.get("scenes_per_second", {})
        lines.append(
            f"| {_cell_code(entry.grammar)} | {thesis_section(entry.description)} | {entry.input_kind} | "
            f"{'yes' if entry.differentiable else 'no'} | "
            f"{_cell(rms.get('8'), '.4f')} | {_cell(rms.get('64'), '.4f')} | "
            f"{_cell(speed.get('8'), ',.0f')} | {_cell(speed.get('64'), ',.0f')} |"
        )
        details += _catalogue_entry(entry, family)
    return "\n".join(lines + [""] + details) + "\n"


def _image_input(family: dict) -> str:
    # Per-estimator input preparation, as the fitted model states it (``model.world_based``,
    # ``model.default_preprocessing``, recorded in catalogue.json): statistics methods use every
    # usable pixel, as the field does; world-based methods the thesis' 5x5 block averages.
    if family.get("world_based") is None:
        return (
            "the model's own default (`model.default_preprocessing`: `ave5` for world-based methods, which need "
            "`--camera`; `pixels` for the statistics methods)"
        )
    if family["world_based"]:
        return (
            f"the thesis' `{family.get('default_preprocessing', 'ave5')}` by default (5x5 block averages of usable "
            "pixels, dark pixels below 2 % of the 99th percentile of R+G+B dropped); needs `--camera`"
        )
    return "every usable pixel by default (`pixels`: not clipped at 0.98 of saturation, no zero channel, no dark rule)"


def _catalogue_entry(entry, family: dict) -> list[str]:
    se = family.get("rg_rms_se", {})
    rms = family.get("rg_rms", {})
    angular = family.get("angular_rms", {})
    ok = family.get("ok_fraction", {})
    speed = family.get("scenes_per_second", {})
    out = [
        f"## {_code(entry.grammar)}",
        "",
        _escape(entry.description[0].upper() + entry.description[1:]) + ".",
        "",
        f"* **Grammar**: {_code(entry.grammar)}; example {_code(entry.example)}.",
        f"* **Thesis section**: {thesis_section(entry.description)}.",
        f"* **Input**: {INPUTS.get(entry.input_kind, entry.input_kind)}.",
        f"* **On images** (`ccjax estimate/correct/evaluate`, `preprocessing.prepare`): {_image_input(family)}.",
        f"* **Differentiable** with respect to its input: {'yes' if entry.differentiable else 'no'}; "
        f"fit traceable (pure JAX in the world's arrays): {'yes' if entry.traceable_fit else 'no'}.",
        "* **Options**: the label's parameters (grammar above); keyword options go to "
        f"`ccjax.fit({entry.example!r}, world, **options)`.",
    ]
    if rms:
        out.append(
            f"* **Thesis world** ({_code(family['example'])}): rg RMS {rms['8']:.4f} ± {se['8']:.4f} at 8 surfaces, "
            f"{rms['64']:.4f} ± {se['64']:.4f} at 64; angular RMS {angular['8']:.2f}° and {angular['64']:.2f}°; "
            f"ok {ok['8']:.1%} and {ok['64']:.1%}."
        )
    if speed:
        load = family.get("load_average")
        # The machine's other load divides the wall-clock speed: say what it was.
        during = "" if load is None else f" (1-minute load average {load:.1f} on the machine while measured)"
        out.append(f"* **Speed**: {speed['8']:,.0f} scenes/s at 8 surfaces, {speed['64']:,.0f} at 64{during}.")
    if "note" in family:
        out.append(f"* **Not measured**: {family['note']}.")
    elif not family:
        out.append("* **Not measured**: no entry in docs/data/catalogue.json yet (regenerate the data).")
    return out + [""]


# -- reproduced thesis tables ------------------------------------------------------------------------


def _columns(rows: list[dict]) -> list[str]:
    seen: list[str] = []
    for row in rows:
        column = row["column"] if "sharpening" not in row else f"{row['column']}@{row['sharpening']}"
        if column not in seen:
            seen.append(column)
    return seen


def _column_of(row: dict) -> str:
    return row["column"] if "sharpening" not in row else f"{row['column']}@{row['sharpening']}"


def table_markdown(table: str, payload: dict | None) -> str:
    """One reproduced table's page.

    Arguments:
        table: the table id.
        payload: the JSON of ``ccjax reproduce T --json`` (``None``: not generated yet).

    Returns:
        The page's markdown (the figure is :func:`table_figure`).
    """
    title = f"# Table {table}: {TABLE_TITLES.get(table, '')}"
    if payload is None:
        return f"{title}\n\nNot generated yet: run `python docs/scripts/generate_data.py --only reproduce`.\n"
    rows = payload["rows"]
    differences = [abs(r["relative_difference"]) for r in rows if r.get("relative_difference") is not None]
    lines = [
        title,
        "",
        f"`ccjax reproduce {table}` on the thesis world (`World.barnard1999`, 1000 scenes per condition), ours",
        "beside the thesis' number. *diff* is ours / thesis − 1; *s.e.* is the sampling error of ours (the",
        "standard error over scenes, by the delta method for an RMS): a difference of a few s.e. is within",
        "what another draw of scenes could give. RGB-valued errors are in the thesis' units (white = 255).",
        "",
    ]
    if differences:
        bands = ", ".join(
            f"{sum(d <= band for d in differences)}/{len(differences)} within ±{band:.0%}"
            for band in (0.10, 0.15, 0.20)
        )
        lines += [f"**Cells**: {bands}; largest |diff| {max(differences):.1%}.", ""]
    lines += [f"![Table {table}: ours against the thesis](table-{table}.png)", ""]
    for column in _columns(rows):
        lines += [
            f"## {_code(column)}",
            "",
            "| method | ours | s.e. | thesis | diff | ok |",
            "| --- | ---: | ---: | ---: | ---: | ---: |",
        ]
        for row in rows:
            if _column_of(row) != column:
                continue
            diff = row.get("relative_difference")
            ok = row.get("ok_fraction")
            lines.append(
                f"| {_code(row['method'])} | {_cell(row['ours'])} | {_cell(row.get('sampling_error'), '.2g')} | "
                f"{_cell(row['thesis'])} | {_cell(diff, '+.1%')} | {_cell(ok, '.0%')} |"
            )
        lines.append("")
    checks = payload.get("checks")
    if checks:
        lines += ["## The thesis' findings", ""]
        lines += [f"* {'holds' if c['holds'] else '**fails**'}: {c['check']} ({c['evidence']})" for c in checks]
        lines.append("")
    return "\n".join(lines)


def table_figure(table: str, payload: dict) -> bytes:
    """Ours against the thesis per column of a table, with ±2 s.e. bars and the line ours = thesis.

    Arguments:
        table: the table id.
        payload: the JSON of ``ccjax reproduce T --json``.

    Returns:
        PNG bytes.
    """
    plt = _pyplot()
    columns = _columns(payload["rows"])
    n = len(columns)
    width = min(n, 4)
    height = (n + width - 1) // width
    fig, axes = plt.subplots(height, width, figsize=(3.6 * width, 3.4 * height), squeeze=False)
    for ax, column in zip(axes.ravel(), columns, strict=False):
        rows = [r for r in payload["rows"] if _column_of(r) == column]
        thesis = [r["thesis"] for r in rows]
        ours = [r["ours"] for r in rows]
        errors = [2 * (r.get("sampling_error") or 0.0) for r in rows]
        ax.errorbar(thesis, ours, yerr=errors, fmt="o", ms=4, capsize=2)
        top = max(max(thesis), max(ours)) * 1.08
        ax.plot([0, top], [0, top], color="grey", lw=0.8)
        ax.set(xlim=(0, top), ylim=(0, top), title=column, xlabel="thesis", ylabel="ours")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.suptitle(f"Table {table}: ours (±2 s.e.) against the thesis")
    fig.tight_layout()
    return _png(fig)


def thesis_index_markdown(payloads: dict) -> str:
    """The overview of the reproduced tables.

    Arguments:
        payloads: table id -> JSON of ``ccjax reproduce`` (or ``None``).

    Returns:
        The page's markdown.
    """
    lines = [
        "# Reproduced thesis tables",
        "",
        "ccjax reruns the synthetic experiments of Barnard (1999) with the thesis' protocol on the thesis",
        "world and sets each number beside the thesis' own. Each page below shows one table, its cells and",
        "a plot of ours against the thesis; [Figures](figures.md) has the error-versus-surfaces curves,",
        "Fig. 10.1 and the Fig. 4.1-style chromaticities. The numbers come from `ccjax reproduce T --json`,",
        "committed under docs/data ([documentation data](../data.md)).",
        "",
        "| table | what | cells | within ±10 % | within ±20 % | largest \\|diff\\| |",
        "| --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for table in TABLES:
        payload = payloads.get(table)
        if payload is None:
            lines.append(f"| [{table}](table-{table}.md) | {TABLE_TITLES[table]} | not generated | | | |")
            continue
        d = [abs(r["relative_difference"]) for r in payload["rows"] if r.get("relative_difference") is not None]
        lines.append(
            f"| [{table}](table-{table}.md) | {TABLE_TITLES[table]} | {len(d)} | {sum(x <= 0.1 for x in d)} | "
            f"{sum(x <= 0.2 for x in d)} | {max(d):.1%} |"
        )
    return "\n".join(lines) + "\n"


# -- figures ---------------------------------------------------------------------------------------


def _compare_series(payload: dict, statistic: str = "rg") -> dict[str, list[tuple[int, float]]]:
    series: dict[str, list[tuple[int, float]]] = {}
    for row in payload["rows"]:
        if row["statistic"] == statistic and row["summary"] == "rms":
            series.setdefault(row["method"], []).append((row["surfaces"], row["value"]))
    return series


def surfaces_figure(payload: dict, methods=None, title: str = "") -> bytes:
    """RMS (r,g) error against the number of surfaces, one line per method.

    Arguments:
        payload: the JSON of ``ccjax compare --json``.
        methods: the methods drawn (default: all).
        title: the figure's title.

    Returns:
        PNG bytes.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.6))
    for method, points in _compare_series(payload).items():
        if methods is not None and method not in methods:
            continue
        points.sort()
        ax.plot([p[0] for p in points], [p[1] for p in points], marker="o", ms=3, label=method)
    ax.set_xscale("log", base=2)
    ax.set(xlabel="number of surfaces", ylabel="RMS (r,g) error", title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _png(fig)


def chromaticity_figure(payload: dict) -> bytes:
    """The thesis world's (r,g) chromaticities in the manner of Barnard (1999) Fig. 4.1.

    Arguments:
        payload: ``docs/data/world-barnard1999.json``.

    Returns:
        PNG bytes.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4), sharex=True, sharey=True)
    panels = [
        ("training illuminants", payload["train"], 10),
        ("test illuminants", payload["test"], 4),
        ("reflectances under the canonical light", payload["reflectances"], 2),
    ]
    for ax, (name, points, size) in zip(axes, panels, strict=True):
        ax.scatter([p[0] for p in points], [p[1] for p in points], s=size, alpha=0.7)
        ax.scatter([payload["canonical"][0]], [payload["canonical"][1]], marker="*", s=120, c="red", label="canonical")
        ax.set(title=f"{name} ({len(points)})", xlabel="r")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("g")
    axes[0].legend()
    fig.suptitle(f"{payload['world']} ({payload['camera']}): (r,g) chromaticities")
    fig.tight_layout()
    return _png(fig)


def figures_markdown(compare: dict | None, world: dict | None) -> str:
    """The figures page.

    Arguments:
        compare: the JSON of ``ccjax compare --json`` on the thesis world (or ``None``).
        world: ``docs/data/world-barnard1999.json`` (or ``None``).

    Returns:
        The page's markdown.
    """
    lines = ["# Figures", ""]
    if compare is not None:
        lines += [
            "## Error against the number of surfaces",
            "",
            f"`ccjax compare --world barnard1999`, {compare.get('n_scenes')} scenes per point: RMS (r,g) error as",
            "the number of surfaces per scene grows (the thesis' Figs. 4.2-4.4 and 6.x plot the same).",
            "",
            "![RMS (r,g) error against the number of surfaces](surfaces.png)",
            "",
            "## Fig. 10.1",
            "",
            "3-D Colour by Correlation (RGB-C-by-C, MAP and MMSE) against its 2-D version and two gamut-mapping",
            "methods, CRULE-MV and ND-ECRULE-SCWIA-12, as the number of surfaces grows (thesis §10.3).",
            "",
            "![Fig. 10.1 reproduced](fig-10-1.png)",
            "",
        ]
    else:
        lines += ["The comparison data are not generated yet (`generate_data.py --only compare`).", ""]
    if world is not None:
        lines += [
            "## Fig. 4.1: the illuminant sets",
            "",
            "The thesis world's training and test illuminants and its reflectances under the canonical light,",
            "in (r,g) (thesis §4.4 and Fig. 4.1: the lights are placed in 0.02 (training) and 0.01 (test) cells).",
            "",
            "![Fig. 4.1-style chromaticities](fig-4-1.png)",
            "",
        ]
    return "\n".join(lines)


# -- the command-line reference --------------------------------------------------------------------------


def cli_markdown(parser: argparse.ArgumentParser | None = None) -> str:
    """The help of ``ccjax`` and of every sub-command, from the argument parsers.

    Arguments:
        parser: the parser (default ``ccjax.cli.build_parser()``).

    Returns:
        The page's markdown.
    """
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal; fix it for a stable page
    if parser is None:
        from ccjax.cli import build_parser

        parser = build_parser()
    lines = [
        "# Command line",
        "",
        "Generated from `ccjax.cli.build_parser()` at build time: what `ccjax COMMAND --help` prints.",
        "",
        "```text",
        parser.format_help().rstrip(),
        "```",
        "",
    ]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                lines += [f"## `ccjax {name}`", "", "```text", sub.format_help().rstrip(), "```", ""]
    return "\n".join(lines)


# -- the mkdocs hook -------------------------------------------------------------------------------------


def generated_pages() -> dict[str, str | bytes]:
    """Every generated file of the site, path (relative to docs/) -> content.

    Returns:
        Markdown pages as text, figures as PNG bytes.
    """
    pages: dict[str, str | bytes] = {"catalogue.md": catalogue_markdown(), "cli.md": cli_markdown()}
    payloads = {table: _load(f"reproduce-{table}.json") for table in TABLES}
    pages["thesis/index.md"] = thesis_index_markdown(payloads)
    for table, payload in payloads.items():
        pages[f"thesis/table-{table}.md"] = table_markdown(table, payload)
        if payload is not None:
            pages[f"thesis/table-{table}.png"] = table_figure(table, payload)
    compare, world = _load("compare-barnard1999.json"), _load("world-barnard1999.json")
    pages["thesis/figures.md"] = figures_markdown(compare, world)
    if compare is not None:
        pages["thesis/surfaces.png"] = surfaces_figure(compare, title="thesis world: RMS (r,g) error")
        pages["thesis/fig-10-1.png"] = surfaces_figure(compare, FIG_10_1, title="Fig. 10.1 (thesis world)")
    if world is not None:
        pages["thesis/fig-4-1.png"] = chromaticity_figure(world)
    return pages


def on_files(files, config):
    """Add the generated pages and figures to the site (mkdocs hook)."""
    from mkdocs.structure.files import File

    for path, content in generated_pages().items():
        files.append(File.generated(config, path, content=content))
    return files
