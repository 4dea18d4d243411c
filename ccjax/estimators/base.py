"""The estimator contract: a fitted model is an ``eqx.Module`` whose ``__call__`` estimates ONE
scene and returns the one :class:`Estimate`: ``model(rgb (P, 3), mask (P,))`` for surface
estimators, ``model(image (H, W, 3), mask (H, W))`` for image estimators; batching is ``jax.vmap``
(:func:`estimate_batch`). Input checks at the Python boundary are in
:mod:`ccjax.estimators.inputs`."""

import abc
import dataclasses
import enum
import typing
from dataclasses import dataclass
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from equinox import AbstractClassVar, AbstractVar
from jax import lax
from jaxtyping import Array, Bool, Float, Int

KINDS = ("surfaces", "image")
"""The input kinds of estimators (``AbstractEstimator.input_kind``)."""

SHAPES = {"surfaces": "rgb (P, 3) with mask (P,)", "image": "image (H, W, 3) with mask (H, W)"}
"""What one scene of each input kind is, for error messages."""

DESCRIBED = {"surfaces": "a surface estimator", "image": "an image estimator"}
"""Each input kind in words, for messages."""


class Status(enum.IntEnum):
    """Why an :class:`Estimate` is what it is (``Estimate.status``).

    ``ESTIMATED`` is the only status with ``ok=True``. ``RELAXED``: the method's own answer broke one
    of its constraints and the nearest admissible answer is given instead: gamut mapping found no
    feasible illuminant and answered from the first relaxed constraint level that had one (thesis
    §4.3.2), the neural net predicted a chromaticity outside the triangle and it was projected in;
    ``NO_DATA``: no usable pixel (all masked, all zero), the answer is the model's fallback light;
    ``EMPTY_SET``: the method's feasible set stayed empty (every relaxation level), fallback light.
    """

    ESTIMATED = 0
    RELAXED = 1
    NO_DATA = 2
    EMPTY_SET = 3


@typing.final
class Estimate(eqx.Module):
    """An illuminant estimate; every estimator returns this one type.

    Attributes:
        illuminant: ``(..., 3)`` camera RGB of a perfect white under the estimated light. Its
            magnitude is meaningful for 3-D methods and arbitrary for chromaticity methods.
        ok: ``(...)`` True exactly where ``status == Status.ESTIMATED``.
        status: ``(...)`` int32 :class:`Status` code saying why.
        relaxation: ``(...)`` how far the method relaxed its constraints to find an answer (the
            gamut methods' level ``eps``; 0 for methods without relaxation).
    """

    illuminant: Float[Array, "... 3"]
    ok: Bool[Array, "..."]
    status: Int[Array, "..."]
    relaxation: Float[Array, "..."]

    def __init__(self, illuminant, ok=None, status=None, relaxation=None):
        """Build from ``status`` (``ok`` follows from it) or, for methods that only know whether
        they had data, from ``ok`` (``False`` means ``Status.NO_DATA``)."""
        self.illuminant = illuminant
        if status is None:
            if ok is None:
                raise ValueError("Estimate: give status or ok")
            status = jnp.where(ok, Status.ESTIMATED, Status.NO_DATA)
        self.status = jnp.asarray(status, jnp.int32)
        self.ok = self.status == Status.ESTIMATED
        if relaxation is None:
            relaxation = jnp.zeros(self.status.shape, jnp.result_type(illuminant))
        self.relaxation = jnp.asarray(relaxation)


@dataclass(frozen=True)
class Padding:
    """How a model's answers and cost depend on the padded size of a surface list, for engines that
    pad scenes of several sizes to one shape (one compiled program for several counts).

    Padding adds masked-out surfaces, which no estimator reads; what can change is a Python branch
    on the scene's size. A model states the sizes where its kernel branches (``budgets``), so an
    engine pads a count only within the interval between two consecutive budgets.

    Attributes:
        budgets: the observation counts at which the kernel takes another branch (the gamut
            engine's observation budgets); empty: the model has no size branch.
        counted_slots: when set, below its smallest budget the kernel reads only a scene's usable
            observations in scenes of at least this many slots (padding costs it almost nothing
            there); ``None``: every slot is read (a padded scene costs its padded size).
    """

    budgets: tuple[int, ...] = ()
    counted_slots: int | None = None

    @staticmethod
    def combine(paddings: "typing.Iterable[Padding]") -> "Padding":
        """The padding rule of several models run on the same scenes: every budget of each, and
        counted slots only when every model with budgets counts them (the largest threshold).

        Arguments:
            paddings: the models' padding rules.

        Returns:
            The combined :class:`Padding`.
        """
        paddings = list(paddings)
        budgets = tuple(sorted({b for p in paddings for b in p.budgets if b > 0}))
        with_budgets = [p for p in paddings if p.budgets]
        counted = [p.counted_slots for p in with_budgets]
        slots = max(counted) if counted and all(c is not None for c in counted) else None  # type: ignore[type-var]
        return Padding(budgets, slots)


NO_PADDING_BRANCH = Padding()
"""The padding rule of a model whose kernel has no branch on the scene's size."""


def _weak(leaf) -> bool:
    return isinstance(leaf, jax.Array) and jax.typeof(leaf).weak_type


def _strong(leaf):
    # convert_element_type to the leaf's own dtype drops the weak flag (traced leaves too).
    return lax.convert_element_type(leaf, leaf.dtype) if _weak(leaf) else leaf


class AbstractEstimator(eqx.Module):
    """A fitted estimator: configuration that changes the trace is static, what can
    be learned is an array, so every model is a valid ``jax.jit`` / ``jax.vmap`` / ``jax.grad``
    argument. Concrete estimators derive from :class:`AbstractSurfaceEstimator` or
    :class:`AbstractImageEstimator` and are final. Every array leaf is strong-typed (a weak-typed
    one, from a Python number, is made strong at construction, same dtype), so a training step
    compiled for the model is not traced again after the optimiser's first update.

    What the execution layer needs to know about a model is declared here as abstract attributes
    (equinox's abstract-variable pattern: each final class states them, as a class constant, a
    field or a property; generic code never probes a model's internals):

    Attributes:
        input_kind: ``"surfaces"`` (a list of RGBs with a mask) or ``"image"`` (``(H, W, 3)``);
            fixed by the two intermediate bases.
        estimates_brightness: True for 3-D methods whose estimate magnitude is meaningful (the
            RGB and R+G+B errors and the RGB mapping error apply to them).
        world_based: True when the answers come from the world's lights, reflectances or
            canonical light as its camera sees them (gamut mapping, Colour by Correlation, the
            nets, DB-GW, AVE-ILLUM, NOTHING): on photographs such a model needs the camera's own
            curves. The statistics methods (grey world, max-RGB, shades of grey, grey edge) use
            the world only for their fallback light.
        default_preprocessing: how the image pipeline prepares a photograph for the model
            (:func:`ccjax.preprocessing.prepare`) when the caller does not say: ``"ave5"``, the
            thesis' 5x5 block averages (§4.6), for world-based methods; ``"pixels"``, every usable
            pixel, for the statistics methods, as the field evaluates them.
        pools_pixels: the estimate is linear in the pixels (grey world), so an image's masked
            mean as a single datum gives the same answer as every pixel, with one fast reduction.
        padding: the :class:`Padding` rule (size branches of the kernel).
        block_size: scenes per vmapped block of :func:`estimate_batch` on each backend
            (``block_size(backend)``; ``None``: one ``vmap`` over the whole batch).
    """

    # Type checkers read dataclass-style annotations as constructor fields, so they are shown
    # class constants; at run time equinox enforces that every final class states each one.
    if typing.TYPE_CHECKING:
        input_kind: ClassVar[str]
        estimates_brightness: ClassVar[bool]
        world_based: ClassVar[bool]
        default_preprocessing: ClassVar[str]
        pools_pixels: ClassVar[bool]
        padding: ClassVar[Padding]
    else:
        input_kind: AbstractClassVar[str]
        estimates_brightness: AbstractVar[bool]
        world_based: AbstractVar[bool]
        default_preprocessing: AbstractVar[str]
        pools_pixels: AbstractClassVar[bool]
        padding: AbstractVar[Padding]

    def __check_init__(self):
        # Every array leaf strong-typed, however the model was built: a weak-typed leaf (a Python
        # number through jnp.asarray / jnp.full, or an eqx converter) changes type at the first
        # optimiser update (weak + strong update = strong), so jit traces a training step again.
        # The value and dtype are kept; only JAX's weak flag goes. Runs after every subclass's
        # own checks (equinox calls each class's __check_init__, the subclass's first).
        for field in dataclasses.fields(self):
            if field.metadata.get("static", False):
                continue
            value = getattr(self, field.name)
            if any(_weak(leaf) for leaf in jax.tree_util.tree_leaves(value)):
                object.__setattr__(self, field.name, jax.tree_util.tree_map(_strong, value))

    @abc.abstractmethod
    def block_size(self, backend: str) -> int | None:
        """Scenes per vmapped block of :func:`estimate_batch` on ``backend``.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"``.

        Returns:
            The block size, or ``None``: one ``vmap`` over the whole batch.
        """

    @abc.abstractmethod
    def __call__(self, x: Float[Array, "..."], mask: Bool[Array, "..."]) -> Estimate:
        """Estimate the light of one scene (its shape is the input kind's, see the subclasses)."""


class AbstractUnblockedEstimator(AbstractEstimator):
    """An estimator whose kernel has no branch on the scene's size: nothing is padded and a batch
    is one ``vmap`` on every backend. Mixed into the intermediates and final classes it fits."""

    padding: ClassVar[Padding] = NO_PADDING_BRANCH

    def block_size(self, backend: str) -> int | None:
        """One ``vmap`` over the whole batch on every backend.

        Arguments:
            backend: ``"cpu"``, ``"gpu"`` or ``"tpu"`` (not used).

        Returns:
            ``None``.
        """
        return None


class AbstractSurfaceEstimator(AbstractEstimator):
    """An estimator of ONE scene given as a list of surface RGBs: ``model(rgb (P, 3), mask (P,))``."""

    input_kind: ClassVar[str] = "surfaces"

    @abc.abstractmethod
    def __call__(self, rgb: Float[Array, "P 3"], mask: Bool[Array, " P"]) -> Estimate:
        """Estimate the light of one scene.

        Arguments:
            rgb: ``(P, 3)`` linear camera RGB, non-negative.
            mask: ``(P,)`` True where a surface is valid.

        Returns:
            The :class:`Estimate`.
        """


class AbstractWorldSurfaceEstimator(AbstractSurfaceEstimator, AbstractUnblockedEstimator):
    """A surface estimator fitted to a world's lights, reflectances or canonical light (gamut
    mapping aside: Colour by Correlation, the nets, NOTHING, AVE-ILLUM): on photographs it gets the
    thesis' 5x5 block averages (§4.6), its kernel has no branch on the scene's size and a batch is
    one ``vmap``. Concrete subclasses state ``estimates_brightness``."""

    world_based: ClassVar[bool] = True
    default_preprocessing: ClassVar[str] = "ave5"
    pools_pixels: ClassVar[bool] = False


class AbstractStatisticsSurfaceEstimator(AbstractSurfaceEstimator, AbstractUnblockedEstimator):
    """A statistics method on surface lists (shades of grey, max-RGB): the world gives only its
    fallback light, it is evaluated on every usable pixel as the field does, its kernel has no
    branch on the scene's size and a batch is one ``vmap``. Concrete subclasses state
    ``estimates_brightness``."""

    world_based: ClassVar[bool] = False
    default_preprocessing: ClassVar[str] = "pixels"
    pools_pixels: ClassVar[bool] = False


class AbstractImageEstimator(AbstractEstimator):
    """An estimator of ONE image: ``model(image (H, W, 3), mask (H, W))`` (spatial methods such as
    grey edge, which need the pixels' neighbours)."""

    input_kind: ClassVar[str] = "image"

    @abc.abstractmethod
    def __call__(self, image: Float[Array, "H W 3"], mask: Bool[Array, "H W"]) -> Estimate:
        """Estimate the light of one image.

        Arguments:
            image: ``(H, W, 3)`` linear camera RGB, non-negative.
            mask: ``(H, W)`` True where a pixel is usable.

        Returns:
            The :class:`Estimate`.
        """


def estimate_batch(model: AbstractEstimator, x: Float[Array, "B ..."], mask: Bool[Array, "B ..."]) -> Estimate:
    """Estimate every scene of a batch: ``jax.vmap(model)(x, mask)``, computed in blocks.

    Arguments:
        model: a surface estimator with ``x (B, P, 3)``, ``mask (B, P)``, or an image estimator
            with ``x (B, H, W, 3)``, ``mask (B, H, W)``.
        x: the batch.
        mask: True where a surface or pixel is valid.

    Returns:
        The batched :class:`Estimate`.

    With ``model.block_size(backend)`` set, blocks of that many scenes are vmapped and the blocks mapped
    one after another (``jax.lax.map``), so each block's intermediates stay in cache: the gamut
    kernel's fine grid is ~2,000 directions per scene, and one vmap over 4,096 scenes streams
    every stage through memory (measured 1.2-1.4x slower at 8 and 64 surfaces). The blocks are
    equal, at most ``block_size`` scenes each (the batch is padded with fewer scenes than there
    are blocks, copies of its first ones, and the result trimmed): ``jax.lax.map`` would vmap a
    remainder separately, a second copy of the model to trace and compile (half the gamut
    engine's compile time). The results are those of the plain vmap.
    """
    x, mask = jnp.asarray(x), jnp.asarray(mask)
    kind = input_kind_of(model)
    ndim = 3 if kind == "surfaces" else 4
    if x.ndim != ndim or x.shape[-1] != 3 or mask.shape != x.shape[:-1]:
        batch = "rgb (B, P, 3) with mask (B, P)" if kind == "surfaces" else "image (B, H, W, 3) with mask (B, H, W)"
        raise ValueError(
            f"x: {type(model).__name__} is {DESCRIBED[kind]} and estimates batches {batch}; "
            f"got shapes {tuple(x.shape)} and {tuple(mask.shape)}"
        )
    size = model.block_size(jax.default_backend())
    n_scenes = x.shape[0]
    if size is None or n_scenes <= size:
        return jax.vmap(model)(x, mask)
    n_blocks = -(-n_scenes // size)
    block = -(-n_scenes // n_blocks)
    pad = n_blocks * block - n_scenes  # < n_blocks <= n_scenes: the copies are real scenes
    x = jnp.concatenate([x, x[:pad]])
    mask = jnp.concatenate([mask, mask[:pad]])
    blocks = (x.reshape(n_blocks, block, *x.shape[1:]), mask.reshape(n_blocks, block, *mask.shape[1:]))
    blocked = jax.lax.map(lambda scenes: jax.vmap(model)(*scenes), blocks)
    return jax.tree_util.tree_map(lambda leaf: leaf.reshape(n_blocks * block, *leaf.shape[2:])[:n_scenes], blocked)


def input_kind_of(model) -> str:
    """The input kind of an estimator (``ValueError`` when ``model`` is not one).

    Arguments:
        model: a fitted estimator.

    Returns:
        ``"surfaces"`` or ``"image"``.
    """
    if not isinstance(model, AbstractEstimator):
        raise ValueError(f"method: expected a fitted estimator (AbstractEstimator), got {type(model).__name__}")
    return model.input_kind


def pairwise_reduce(values: Float[Array, "P ..."], op) -> Float[Array, "..."]:
    """Reduce over the leading axis by repeated halving, ``op(first half, second half)``.

    Equivalent to ``jnp.sum`` / ``jnp.max`` over axis 0 for ``op = jnp.add`` / ``jnp.maximum`` on
    non-negative data (odd lengths are padded with zeros), but each step is an element-wise op on
    contiguous blocks, which XLA vectorises well; a direct reduction over the surface axis with a
    trailing RGB axis of 3 does not (2–3x slower on CPU, measured in ``benchmarks/simple.py``).

    Arguments:
        values: ``(P, ...)`` the values to reduce over their leading axis.
        op: the element-wise binary reduction (``jnp.add``, ``jnp.maximum``).

    Returns:
        The reduction, ``values.shape[1:]``.
    """
    while values.shape[0] > 1:
        if values.shape[0] % 2:
            values = jnp.concatenate([values, jnp.zeros((1, *values.shape[1:]), values.dtype)])
        half = values.shape[0] // 2
        values = op(values[:half], values[half:])
    return values[0]


def with_fallback(illuminant: Float[Array, "3"], usable, fallback: Float[Array, "3"]) -> Estimate:
    """Return ``illuminant`` where ``usable``, else ``fallback`` with ``ok=False`` (never NaN).

    The estimate must also be finite with a positive sum. The test is scale-free (a sum above 0,
    not above an absolute threshold): a scene scaled by 1e-12 is still a scene, and the estimates
    of the statistics methods scale with it. The sum, not the largest channel: a sharpened
    estimate can have a negative channel, and Table 5.1's protocol falls back when the sum is not
    positive.

    Arguments:
        illuminant: ``(3,)`` the estimate.
        usable: a boolean scalar: whether the method produced an estimate.
        fallback: ``(3,)`` the estimate used otherwise.

    Returns:
        The :class:`Estimate`, ``ok`` False when the fallback was taken.
    """
    usable = usable & jnp.all(jnp.isfinite(illuminant)) & (jnp.sum(illuminant) > 0)
    safe = jnp.where(usable, jnp.nan_to_num(illuminant), fallback)
    return Estimate(illuminant=safe, ok=usable)
