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
