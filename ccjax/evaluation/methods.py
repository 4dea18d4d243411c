"""Which methods may score which folders of photographs: a label whose fit is only training's
starting point is refused unless the protocol trains it, and a trained model file only scores
folders of the camera it was trained for (a camera-conditioned one, any folder whose camera is
named).
"""

from __future__ import annotations

import pathlib
from collections.abc import Sequence

from ccjax.evaluation.scored_folder import MODEL_SUFFIX

__all__ = ["check_methods", "refuse_unbound"]


def refuse_unbound(method: str, record: dict, folders: Sequence) -> str | None:
    """Refuse a camera-conditioned model file (record ``conditioned: true``) on a folder without a
    camera (it is bound to the folder's camera at load).

    Arguments:
        method: the model file.
        record: its record.
        folders: the folders (:class:`~ccjax.evaluation.FolderSet`) it will score.

    Returns:
        The camera the record names (None for a conditioned model, or one trained without curves).

    Raises:
        ValueError: naming the model and the folders without a camera.
    """
    without = [folder.label for folder in folders if folder.camera is None]
    if record.get("conditioned") is True and without:
        raise ValueError(
            f"methods: model {method} serves any camera given its name (any-camera); name the camera of "
            f"{', '.join(without)} (--camera or --camera-for)"
        )
    return record.get("camera")


def check_methods(methods: Sequence[str], folders: Sequence) -> None:
    """Refuse an untrained label (:func:`ccjax.estimators.registry.refuse_untrained`: the protocol
    trains it) and a trained model file scored on a folder taken with another camera than the one
    its record names (a model learns its camera's raw space; another camera's is another problem).

    Arguments:
        methods: labels and model files.
        folders: the folders (:class:`~ccjax.evaluation.FolderSet`), each with its camera (None: not
            given, not checked).

    Returns:
        None.

    Raises:
        ValueError: naming ``methods`` and the label, or the model, its camera and the folder's.
    """
    from ccjax._cache import read_model_metadata
    from ccjax.estimators.registry import refuse_untrained

    for method in methods:
        if not method.endswith(MODEL_SUFFIX):
            refuse_untrained(method, "methods")
            continue
        if not pathlib.Path(method).is_file():
            raise ValueError(f"methods: no such model file: {method}")
        camera = refuse_unbound(method, read_model_metadata(pathlib.Path(method)), folders)
        for folder in folders:
            if folder.camera is not None and camera is not None and folder.camera != camera:
                raise ValueError(
                    f"methods: model {method} was trained for the {camera}, but folder {folder.label}'s camera is "
                    f'the {folder.camera}; train one for it (ccjax train ... --target-camera "{folder.camera}")'
                )
