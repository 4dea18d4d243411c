"""Synthetic scenes (Barnard 1999 §4.7): surface lists drawn from a world
(:mod:`ccjax.scenes.surfaces`) and Mondrian images rendered from its spectra
(:mod:`ccjax.scenes.mondrian`).

:func:`draw_scene` is the one function that draws a surface-list scene's light and surfaces:
:func:`sample`, :func:`sample_batch` (hence the sweeps) and the chapter-5 experiment use it, so
the same key gives the same scene in each. Mondrian images split their keys differently (one
more key for the layout) and draw with :func:`draw_without_replacement` directly.

Rendering options (:mod:`ccjax.scenes.options`): :class:`Specular` and :class:`Metallic`
highlights (§4.7, §8.3), :class:`Fluorescent` surfaces (§7.3), :class:`ShotNoise` and clipping, all
held by one :class:`SceneOptions` (what a synthetic source renders, beside its keys). Material
colours live in :class:`SceneTables` (:mod:`ccjax.scenes.tables`;
``SceneTables.from_world(world, metals=True, fluorescent=model)``, with ``model`` a
:class:`RadianceModel` from :mod:`ccjax.materials`).
"""

from ccjax.scenes.mondrian import MondrianImages as MondrianImages
from ccjax.scenes.mondrian import mondrian_batch as mondrian_batch
from ccjax.scenes.mondrian import mondrian_layout as mondrian_layout
from ccjax.scenes.mondrian import render_mondrian as render_mondrian
from ccjax.scenes.mondrian import sample_mondrians as sample_mondrians
from ccjax.scenes.options import Fluorescent as Fluorescent
from ccjax.scenes.options import Metallic as Metallic
from ccjax.scenes.options import SceneOptions as SceneOptions
from ccjax.scenes.options import ShotNoise as ShotNoise
from ccjax.scenes.options import Specular as Specular
from ccjax.scenes.options import require_count as require_count
from ccjax.scenes.options import resolve_materials as resolve_materials
from ccjax.scenes.options import resolve_options as resolve_options
from ccjax.scenes.surfaces import SceneDraw as SceneDraw
from ccjax.scenes.surfaces import SceneKeys as SceneKeys
from ccjax.scenes.surfaces import Scenes as Scenes
from ccjax.scenes.surfaces import draw_scene as draw_scene
from ccjax.scenes.surfaces import draw_scenes as draw_scenes
from ccjax.scenes.surfaces import draw_without_replacement as draw_without_replacement
from ccjax.scenes.surfaces import sample as sample
from ccjax.scenes.surfaces import sample_batch as sample_batch
from ccjax.scenes.surfaces import sample_batch_slots as sample_batch_slots
from ccjax.scenes.surfaces import sample_one as sample_one
from ccjax.scenes.surfaces import scene_keys as scene_keys
from ccjax.scenes.surfaces import sweep_keys as sweep_keys
from ccjax.scenes.tables import RadianceModel as RadianceModel
from ccjax.scenes.tables import SceneTables as SceneTables
