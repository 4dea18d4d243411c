"""Synthetic scenes (Barnard 1999 §4.7): surface lists drawn from a world
(:mod:`ccjax.scenes._surfaces`) and Mondrian images rendered from its spectra
(:mod:`ccjax.scenes._mondrian`).

:func:`draw_scene` is the one function that draws a surface-list scene's light and surfaces:
:func:`sample`, :func:`sample_batch` (hence the sweeps) and the chapter-5 experiment use it, so
the same key gives the same scene in each. Mondrian images split their keys differently (one
more key for the layout) and draw with :func:`draw_without_replacement` directly.

Rendering options (:mod:`ccjax.scenes._options`): :class:`Specular` and :class:`Metallic`
highlights (§4.7, §8.3), :class:`Fluorescent` surfaces (§7.3), :class:`ShotNoise` and clipping, all
held by one :class:`SceneOptions` (what a synthetic source renders, beside its keys). Material
colours live in :class:`SceneTables` (:mod:`ccjax.scenes._tables`;
``SceneTables.from_world(world, metals=True, fluorescent=model)``, with ``model`` a
:class:`RadianceModel` from :mod:`ccjax.materials`).
"""

from ccjax.scenes._mondrian import MondrianImages, mondrian_batch, mondrian_layout, render_mondrian, sample_mondrians
from ccjax.scenes._options import Fluorescent, Metallic, SceneOptions, ShotNoise, Specular, require_count
from ccjax.scenes._surfaces import (
    SceneDraw,
    SceneKeys,
    Scenes,
    draw_scene,
    draw_scenes,
    draw_without_replacement,
    sample,
    sample_batch,
    sample_batch_slots,
    sample_one,
    scene_keys,
    sweep_keys,
)
from ccjax.scenes._tables import RadianceModel, SceneTables, require_tables

__all__ = [
    "Fluorescent",
    "Metallic",
    "MondrianImages",
    "RadianceModel",
    "SceneDraw",
    "SceneKeys",
    "SceneOptions",
    "SceneTables",
    "Scenes",
    "ShotNoise",
    "Specular",
    "draw_scene",
    "draw_scenes",
    "draw_without_replacement",
    "mondrian_batch",
    "mondrian_layout",
    "render_mondrian",
    "require_count",
    "require_tables",
    "sample",
    "sample_batch",
    "sample_batch_slots",
    "sample_mondrians",
    "sample_one",
    "scene_keys",
    "sweep_keys",
]
