"""``ccjax compare``'s command line: what ``--methods`` takes, and machine-readable output on stdout."""

from __future__ import annotations

from ccjax import cli


def test_image_estimators_are_refused_naming_the_command_that_scores_them(capsys):
    """``compare --methods GW,grey-edge-1-6-2``: one line naming the image estimator and
    ``ccjax evaluate``, before anything is fitted; ``--help`` says what ``--methods`` takes."""
    assert cli.main(["compare", "--methods", "GW,grey-edge-1-6-2,FFCC", "--scenes", "5", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "--methods: grey-edge-1-6-2, FFCC: image estimators" in err and "ccjax evaluate DIR" in err
    try:
        cli.main(["compare", "--help"])
    except SystemExit:
        pass
    help_text = " ".join(capsys.readouterr().out.split())
    assert (
        "labels of surface estimators" in help_text
        and "FFCC) are scored on images with `ccjax evaluate DIR`" in help_text
    )


def test_json_and_csv_to_standard_output_hold_only_the_data(tmp_path, monkeypatch, capsys):
    """``--json -`` / ``--csv -``: stdout parses as a whole (``json.loads``, ``csv``); the tables for
    people go to stderr; both to stdout at once is one error line."""
    import csv
    import io
    import json

    monkeypatch.setenv("CCJAX_CACHE", str(tmp_path))
    argv = ["compare", "--methods", "GW,RETINEX", "--scenes", "20", "--surfaces", "4,8", "--no-progress"]
    assert cli.main([*argv, "--json", "-"]) == 0
    captured = capsys.readouterr()
    data = json.loads(captured.out)
    assert data and "world: " in captured.err and "relaxed / fell back" in captured.err
    assert cli.main([*argv, "--csv", "-"]) == 0
    captured = capsys.readouterr()
    rows = list(csv.DictReader(io.StringIO(captured.out)))
    assert rows and {"GW", "RETINEX"} <= {row.get("method") for row in rows}
    assert cli.main([*argv, "--json", "-", "--csv", "-"]) == 2
    assert capsys.readouterr().err.strip() == (
        "ccjax compare: error: --json, --csv: give '-' (standard output) to one of them; write the other to a file"
    )
