"""The text tables of a folder evaluation with folds: the field's statistics per fold and pooled,
and what each fold's training did (:class:`ccjax.evaluation.FolderEvaluation`'s
report)."""

from __future__ import annotations

import typing

import numpy as np

if typing.TYPE_CHECKING:  # the results module loads on use
    from ccjax.evaluation.image_results import ImageResults

__all__ = ["fold_table", "training_table"]


def fold_table(results: ImageResults, fold_of: np.ndarray) -> str:
    """The field's statistics (degrees) of every method per fold and pooled.

    Arguments:
        results: the evaluation's results.
        fold_of: ``(N,)`` the fold of each of ``results.paths``.

    Returns:
        The table's text.
    """
    from ccjax.metrics import FIELD_STATISTICS, summarise

    width = max([24, *(len(method) + 2 for method in results.estimates)])
    lines = [
        "angular error (degrees) per fold and pooled",
        f"{'method':<{width}}{'fold':>7}{'images':>8}" + "".join(f"{name:>9}" for name in FIELD_STATISTICS),
    ]
    folds = sorted(set(fold_of.tolist()))
    for method in results.estimates:
        errors = results.angular(method)
        for fold in [*folds, None]:
            chosen = errors if fold is None else errors[fold_of == fold]
            if not len(chosen):
                continue
            lines.append(
                f"{method:<{width}}{'pooled' if fold is None else fold:>7}{len(chosen):>8}"
                + "".join(f"{summarise(chosen, name):9.3f}" for name in FIELD_STATISTICS)
            )
    return "\n".join(lines)


def training_table(validations: dict) -> str:
    """What each fold's training did: images trained on and scored, epochs, seconds.

    Arguments:
        validations: ``{label: CrossValidation}``.

    Returns:
        The table's text.
    """
    lines = [
        "training within folds (each fold's model never sees the fold it scores)",
        f"{'method':<24}{'fold':>5}{'trained on':>12}{'scored':>8}{'epochs':>8}{'best':>6}{'wall s':>9}{'cpu s':>9}"
        f"{'stop-split median: start':>26}{'best':>7}",
    ]
    for label, validation in validations.items():
        for result in validation.folds:
            row, log = result.summary(), result.log
            # A fit without a stopping split (FFCC's regularised L-BFGS) has no epochs to report.
            stopping = (
                f"{row['epochs']:>8}{row['best_epoch']:>6}",
                f"{log.initial_median:>26.3f}{min([log.initial_median, *log.heldout_median]):>7.3f}",
            )
            if log.n_heldout == 0:
                stopping = (f"{'-':>8}{'-':>6}", f"{'-':>26}{'-':>7}")
            lines.append(
                f"{label:<24}{row['fold']:>5}{row['n_train']:>12}{row['n_test']:>8}{stopping[0]}"
                f"{row['train_seconds']:>9.1f}{row['train_cpu_seconds']:>9.1f}{stopping[1]}"
            )
    lines.append(
        "(trained on: the other folds' images, an early-stopping split of them included; stop-split median: "
        "angular error on that split before training and at the best epoch; '-': the method trains without "
        "a stopping split)"
    )
    return "\n".join(lines)
