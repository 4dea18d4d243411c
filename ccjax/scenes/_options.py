"""Scene options: how the surfaces of a synthetic scene are rendered once drawn (Barnard 1999 §4.7).

Each option is a frozen (hashable) dataclass, so options are static arguments of the jitted
samplers: :class:`Specular` highlights (§4.7, ch. 8), :class:`ShotNoise` (the chapter 3 noise
model), a clip level, :class:`Metallic` highlights (§8.3) and :class:`Fluorescent` surfaces
(§7.3). :class:`SceneOptions` holds all of them: the one value that says, beside the keys, what a
synthetic scene source renders (a sweep, a thesis table's condition).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ccjax.limits import require_count as require_count
from ccjax.materials import METAL_MAX_AMOUNT, METAL_PROBABILITY


@dataclass(frozen=True)
class Specular:
    """Dielectric specularities (Barnard 1999 §4.7, ch. 8): each surface is specular with
    ``probability`` and then gains ``U(0, max_amount)`` times a perfect white reflectance.

    Attributes:
        probability: chance, in ``[0, 1]``, that a surface is specular (thesis: 0.25).
        max_amount: upper end of the uniform highlight strength, in units of a perfect white
            reflectance (thesis: 2, so a highlight adds up to twice a white's RGB); ``>= 0``.
    """

    probability: float = 0.25
    max_amount: float = 2.0

    def __post_init__(self):
        _require_real(self.probability, "Specular.probability", "a probability in [0, 1]", lambda v: 0 <= v <= 1)
        _require_real(self.max_amount, "Specular.max_amount", "a finite number >= 0", lambda v: v >= 0)


@dataclass(frozen=True)
class ShotNoise:
    """Chapter 3 noise model on the unit scale: ``rho + sqrt(a * rho + b) * N(0, 1)``, clamped at
    zero (a sensor cannot report a negative count). Defaults: ``a = 2e-6``, ``b = (0.05/255)^2``.

    Attributes:
        a: signal-dependent (shot) variance per unit of response, so the variance grows linearly
            with ``rho``; on the unit scale (``rho = 1`` is 255 in thesis units); ``>= 0``.
        b: signal-independent variance (the noise floor at ``rho = 0``), on the unit scale (the
            default is a standard deviation of 0.05 in thesis units, white = 255); ``>= 0``.
    """

    a: float = 2e-6
    b: float = (0.05 / 255.0) ** 2

    def __post_init__(self):
        _require_real(self.a, "ShotNoise.a", "a finite number >= 0", lambda v: v >= 0)
        _require_real(self.b, "ShotNoise.b", "a finite number >= 0", lambda v: v >= 0)


@dataclass(frozen=True)
class Metallic:
    """Metallic highlights (Barnard 1999 §8.3; spec ch08-12 A11): each surface gets one with
    ``probability``, adding ``U(0, max_amount)`` times a metal spectrum drawn uniformly from the
    tables' metals. By default the spectra are the metals' own reflectances (at most 1), so a
    highlight is at most ``max_amount`` times as bright as a perfect white in every channel: the
    thesis' "up to a factor of four times as bright as a perfect white" (see
    :func:`ccjax.materials.scene_metal_spectra`).

    Attributes:
        probability: chance that a surface gets a highlight.
        max_amount: largest multiple of the metal spectrum added.
    """

    probability: float = METAL_PROBABILITY
    max_amount: float = METAL_MAX_AMOUNT

    def __post_init__(self):
        _require_real(self.probability, "Metallic.probability", "a probability in [0, 1]", lambda v: 0 <= v <= 1)
        _require_real(self.max_amount, "Metallic.max_amount", "a finite number >= 0", lambda v: v >= 0)


@dataclass(frozen=True)
class Fluorescent:
    """Fluorescent surfaces (Barnard 1999 §7.3, "30 % of the randomly selected surfaces"; A21):
    each surface slot independently becomes, with ``probability``, one of the tables' fluorescent
    surfaces chosen uniformly (a surface may then occur twice in a scene: there are only nine).

    Attributes:
        probability: chance that a surface slot is fluorescent.
    """

    probability: float = 0.3

    def __post_init__(self):
        _require_real(self.probability, "Fluorescent.probability", "a probability in [0, 1]", lambda v: 0 <= v <= 1)


def _require_real(value, name: str, expected: str, accept) -> None:
    """Raise a ``ValueError`` naming ``name`` unless ``value`` is a finite real number that ``accept``s."""
    if isinstance(value, bool) or (not isinstance(value, (int, float)) and not hasattr(value, "__float__")):
        raise ValueError(f"{name}: expected {expected}, got {value!r}")
    number = float(value)
    if not math.isfinite(number) or not accept(number):
        raise ValueError(f"{name}: expected {expected}, got {value!r}")


def resolve_materials(metallic, fluorescent) -> tuple[Metallic | None, Fluorescent | None]:
    """Validate and normalise the material options (``True`` -> the thesis recipe).

    Arguments:
        metallic: a :class:`Metallic`, ``True``, or ``None`` / ``False``.
        fluorescent: a :class:`Fluorescent`, ``True``, or ``None`` / ``False``.

    Returns:
        ``(metallic or None, fluorescent or None)``.
    """
    metallic = Metallic() if metallic is True else (metallic or None)
    fluorescent = Fluorescent() if fluorescent is True else (fluorescent or None)
    if metallic is not None and not isinstance(metallic, Metallic):
        raise ValueError(f"metallic: expected True, None or a Metallic, got {metallic!r}")
    if fluorescent is not None and not isinstance(fluorescent, Fluorescent):
        raise ValueError(f"fluorescent: expected True, None or a Fluorescent, got {fluorescent!r}")
    return metallic, fluorescent


def resolve_options(specular, noise, clip) -> tuple[Specular | None, ShotNoise | None]:
    """Validate and normalise the scene options (``True`` -> the default recipe).

    Arguments:
        specular: a :class:`Specular`, ``True``, or ``None`` / ``False``.
        noise: a :class:`ShotNoise`, ``True``, or ``None`` / ``False``.
        clip: the clip level, or ``None``.

    Returns:
        ``(specular or None, noise or None)``.
    """
    specular = Specular() if specular is True else (specular or None)
    noise = ShotNoise() if noise is True else (noise or None)
    if specular is not None:
        if not isinstance(specular, Specular):
            raise ValueError(f"specular: expected True, None or a Specular, got {specular!r}")
        if not 0 <= specular.probability <= 1 or specular.max_amount < 0:
            raise ValueError(f"specular: probability must be in [0, 1] and max_amount >= 0, got {specular}")
    if noise is not None:
        if not isinstance(noise, ShotNoise):
            raise ValueError(f"noise: expected True, None or a ShotNoise, got {noise!r}")
        if noise.a < 0 or noise.b < 0:
            raise ValueError(f"noise: a and b must be non-negative, got {noise}")
    if clip is not None and not (isinstance(clip, (int, float)) and clip > 0):
        raise ValueError(f"clip: expected a positive level on the unit scale, got {clip!r}")
    return specular, noise


@dataclass(frozen=True)
class SceneOptions:
    """Every rendering option of a synthetic scene, in one static (hashable) value (Barnard 1999
    §4.7, §7.3, §8.3). The recipe's order is :func:`ccjax.scenes.sample_one`'s: fluorescent surfaces
    replace drawn reflectances, then dielectric and metallic highlights are added, then noise,
    then clipping.

    :meth:`resolve` builds one from the flags of :func:`ccjax.scenes.sample` and
    :func:`ccjax.experiments.sweep` (``True``: the option's thesis recipe, the class defaults;
    ``False``: off). Metallic highlights and fluorescent surfaces need their
    colours in the :class:`~ccjax.scenes.SceneTables` the scenes are drawn from
    (``SceneTables.from_world(world, metals=..., fluorescent=...)``).

    Attributes:
        specular: dielectric highlights (:class:`Specular`), or ``None``.
        noise: shot noise (:class:`ShotNoise`), or ``None``.
        clip: clip level on the unit scale (thesis levels 250, 300, 400 are ``250/255`` ...):
            surfaces with any channel above it are masked out; ``None``: no clipping.
        metallic: metallic highlights (:class:`Metallic`), or ``None``.
        fluorescent: fluorescent surfaces (:class:`Fluorescent`), or ``None``.
    """

    specular: Specular | None = None
    noise: ShotNoise | None = None
    clip: float | None = None
    metallic: Metallic | None = None
    fluorescent: Fluorescent | None = None

    def __post_init__(self):
        resolve_options(self.specular, self.noise, self.clip)
        resolve_materials(self.metallic, self.fluorescent)

    @classmethod
    def resolve(
        cls,
        specular: Specular | bool | None = None,
        noise: ShotNoise | bool | None = None,
        clip: float | None = None,
        metallic: Metallic | bool | None = None,
        fluorescent: Fluorescent | bool | None = None,
    ) -> SceneOptions:
        """The options from flags or values (``True``: the thesis recipe; ``False``/``None``: off).

        Arguments:
            specular, noise, clip, metallic, fluorescent: as the attributes, or ``True``/``False``.

        Returns:
            The :class:`SceneOptions`.
        """
        specular, noise = resolve_options(specular, noise, clip)
        metallic, fluorescent = resolve_materials(metallic, fluorescent)
        return cls(specular, noise, clip, metallic, fluorescent)
