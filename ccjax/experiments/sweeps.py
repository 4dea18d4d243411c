"""Sweeps over synthetic scenes: every method on the same scenes, per number of surfaces.

The protocol is the thesis' (Barnard 1999 §4.7): for each number of surfaces, ``n_scenes`` scenes
under test illuminants, every method run on the same scenes, errors aggregated per scene and then
summarised (RMS is the thesis' aggregate). :func:`sweep` resolves its methods (labels are fitted
through :mod:`ccjax.runs.store`) and runs them on one synthetic source through the engine
(:func:`ccjax.runs.synthetic.run_synthetic`: chunking, padding, compile-ahead, sharding, the disk
cache of cells); scenes come from per-scene keys, so a sweep's numbers do not depend on its chunk
size or on how the scene axis is sharded over devices.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax

from ccjax import limits
from ccjax.estimators import inputs, registry
from ccjax.estimators.base import AbstractEstimator
from ccjax.experiments.sweep_results import SweepResult
from ccjax.runs import store
from ccjax.runs.synthetic import SyntheticSource, run_synthetic
from ccjax.scenes import Fluorescent, Metallic, RadianceModel, SceneOptions, ShotNoise, Specular
from ccjax.world import World


def is_registered(label: str) -> bool:
    """Whether ``label`` names a registered estimator (see ``ccjax methods``).

    Arguments:
        label: an estimator label.

    Returns:
        True when a registry family's grammar accepts it.
    """
    try:
        registry.lookup(label)
        return True
    except ValueError:
        return False


def weights_ready(label: str, world: World) -> bool:
    """False for a learned method whose weights are not cached for ``world`` (never train silently).

    Default method sets (``ccjax compare``, ``ccjax reproduce``) include the neural net (Barnard
    1999 §4.5.5) only once ``ccjax train-net`` has cached its weights.

    Arguments:
        label: an estimator label.
        world: the world the weights must have been trained for.

    Returns:
        True for every label but a net's without cached weights.
    """
    from ccjax.estimators import neural

    return not neural.is_net_label(label) or neural.has_weights(world, label)


def runnable_methods(labels: Sequence[str], world: World) -> list[str]:
    """The labels of ``labels`` that are registered and, if learned, have cached weights.

    Arguments:
        labels: candidate labels, in order.
        world: the world of the weights.

    Returns:
        The runnable labels, in the given order.
    """
    return [label for label in labels if is_registered(label) and weights_ready(label, world)]


def require_surface_estimator(label: str, model: AbstractEstimator) -> None:
    """Refuse an image estimator where synthetic surface lists are the input.

    Sweeps sample scenes as lists of surface RGBs (Barnard 1999 §4.7); an image estimator (grey
    edge) needs ``(H, W, 3)`` images with neighbouring pixels, so it is run through the image
    experiments (``ccjax evaluate``, ``ccjax indexing``) instead.

    Arguments:
        label: the model's label (named in the error).
        model: a fitted estimator.

    Raises:
        ValueError: naming ``label`` when ``model`` is an image estimator.
    """
    inputs.require_kind(model, "surfaces", f"methods: {label!r}")


def resolve_methods(
    world: World, methods, counts: dict | None = None, *, progress: bool = False
) -> list[tuple[str, AbstractEstimator]]:
    """``(label, surface estimator)`` pairs from labels, estimators or pairs (labels are fitted
    through the store's cache of fits, :func:`ccjax.runs.store.fit_with_source`).

    Arguments:
        world: the world labels are fitted to.
        methods: labels, fitted surface estimators, or ``(label, estimator)`` pairs.
        counts: if given, ``"cached"`` and ``"fitted"`` are incremented per label.
        progress: show a progress bar naming the method being fitted (fits of the gamut and
            correlation families take seconds to minutes before any scene runs).

    Returns:
        The pairs, in order.

    Raises:
        ValueError: an empty list, an unknown item, an image estimator, or the label of a method
            that must be trained first (:func:`ccjax.estimators.registry.refuse_untrained`).
    """
    from tqdm.auto import tqdm

    resolved, methods = [], list(methods)
    registry.refuse_untrained([method for method in methods if isinstance(method, str)], "methods")
    # Counted by hand: a bar that wraps the iterable shows its count only when it redraws on its
    # own schedule, so naming the method (a redraw) showed 0 of N until the fits were done.
    bar = tqdm(total=len(methods), desc="fit", unit="method", disable=not progress, leave=False)
    for method in methods:
        if isinstance(method, str):
            bar.set_postfix_str(method)
            model, hit = store.fit_with_source(method, world)
            if counts is not None:
                name = "cached" if hit else "fitted"
                counts[name] = counts.get(name, 0) + 1
            resolved.append((method, model))
        elif isinstance(method, tuple) and len(method) == 2 and isinstance(method[1], AbstractEstimator):
            resolved.append(method)
        elif isinstance(method, AbstractEstimator):
            resolved.append((type(method).__name__, method))
        else:
            raise ValueError(f"methods: expected labels, Estimators or (label, Estimator) pairs, got {method!r}")
        require_surface_estimator(*resolved[-1])
        bar.update(1)
    bar.close()
    if not resolved:
        raise ValueError("methods: empty")
    return resolved


def sweep(
    world: World,
    methods: Sequence,
    n_surfaces: Sequence[int] = (4, 8, 16, 32, 64),
    n_scenes: int = 1000,
    key: jax.Array | None = None,
    *,
    specular: Specular | bool | None = None,
    noise: ShotNoise | bool | None = None,
    clip: float | None = None,
    metallic: Metallic | bool | None = None,
    fluorescent: Fluorescent | bool | None = None,
    metals=None,
    fluorescent_surfaces: RadianceModel | None = None,
    chunk_size: int | None = None,
    mesh: jax.sharding.Mesh | None = None,
    progress: bool = True,
    cache: bool = False,
) -> SweepResult:
    """Run every method on the same synthetic scenes for each number of surfaces (Barnard 1999 §4.7).

    Arguments:
        world: the world.
        methods: labels (``"GW"``), fitted surface estimators, or ``(label, estimator)`` pairs.
            Image estimators (grey edge) are refused with a ValueError.
        n_surfaces: numbers of surfaces per scene.
        n_scenes: scenes per number of surfaces (1000 in the thesis; at most
            :data:`ccjax.limits.SCENES`, and times the surface counts and the methods at most
            :data:`ccjax.limits.SCENE_RESULTS`).
        key: PRNG key (default ``jax.random.key(0)``).
        specular, noise, clip, metallic, fluorescent: the scene options
            (:meth:`ccjax.scenes.SceneOptions.resolve`; ``True``: the thesis recipe).
        metals: ``(M, 101)`` spectra of the metallic highlights (default: the six metals'
            reflectances).
        fluorescent_surfaces: the fluorescent surfaces' :class:`~ccjax.scenes.RadianceModel`
            (default: their characterisation from the world's lights, as the thesis rendered its
            fluorescent scenes, §7.3, and as ``ccjax reproduce`` does).
        chunk_size: scenes per compiled chunk (default: about 4M surfaces per chunk), which bounds
            memory whatever ``n_scenes`` is.
        mesh: optional ``jax.sharding.Mesh`` with one axis; the scene axis of every chunk is sharded
            over it (multi-device or multi-host).
        progress: show a progress bar.
        cache: read and write each (label, surface count) cell's per-scene errors in the disk
            cache (``<cache>/sweeps``), keyed by everything they depend on (the label, the world,
            the scene options and key, the counts, padded and chunk sizes, ccjax's code, JAX's
            version and backend), so a repeated sweep computes only the cells it has not seen.
            Only labelled methods on one device are cached (models given as objects, and sharded
            sweeps, are always computed); the count of cells read is
            :attr:`SweepResult.cells_from_cache`.

    Returns:
        A :class:`SweepResult`: its tables (:meth:`SweepResult.report`, ``to_csv``, ``to_json``) and
        its figure, one call: :func:`ccjax.experiments.plot_sweep`.

    Raises:
        ValueError: a count out of range or past its limit (``n_scenes`` times the surface
            counts and the methods past :data:`ccjax.limits.SCENE_RESULTS` is refused before
            anything is fitted), or a method that is not a surface estimator.
    """
    if not isinstance(n_scenes, int) or n_scenes < 1:
        raise ValueError(f"n_scenes: expected a positive integer, got {n_scenes!r}")
    n_reflectances = int(world.reflectances.shape[0])
    surfaces = [int(n) for n in n_surfaces]
    if not surfaces or any(not 1 <= n <= n_reflectances for n in surfaces):
        raise ValueError(f"n_surfaces: expected integers in [1, {n_reflectances}], got {list(n_surfaces)}")
    # Each (method, surface count) cell keeps a few numbers per scene until the sweep ends.
    cells = ((n_scenes, "scenes"), (len(set(surfaces)), "surface counts"), (len(methods), "methods"))
    limits.require_product(cells, "n_scenes", limits.SCENE_RESULTS)
    options = SceneOptions.resolve(specular, noise, clip, metallic, fluorescent)
    counts: dict[str, int] = {}
    resolved = resolve_methods(world, methods, counts, progress=progress)
    key = jax.random.key(0) if key is None else key
    source = SyntheticSource(key, tuple(surfaces), n_scenes, options, metals, fluorescent_surfaces)
    run = run_synthetic(
        world,
        [model for _, model in resolved],
        [source],
        labels=[method if isinstance(method, str) else None for method in methods],
        chunk_size=chunk_size,
        mesh=mesh,
        progress=progress,
        cache=cache,
        desc="sweep",
    )
    result = SweepResult(
        methods=[label for label, _ in resolved],
        surfaces=surfaces,
        n_scenes=n_scenes,
        fits_from_cache=counts.get("cached", 0),
        fits_fitted=counts.get("fitted", 0),
        cells_from_cache=run.cells_from_cache,
    )
    for n in surfaces:
        for position, (label, _) in enumerate(resolved):
            result.errors.setdefault(label, {})[n] = run.errors[0][n][position]
    return result
