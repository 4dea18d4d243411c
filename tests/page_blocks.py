"""The runnable blocks of a documentation page, in page order, and the stand-in photograph sets its
commands name: what tests/test_docs.py runs as a reader pastes a page."""

from __future__ import annotations

import dataclasses
import re

SHELLS = ("bash", "sh", "console")
"""Fence languages whose lines are shell commands (a ``console`` block: only its ``$ `` lines)."""

NOT_RUN = re.compile(r"<!--\s*not run:\s*(?P<reason>.+?)\s*-->", re.S)
"""The mark, in the lines right before a block, of a block a page does not mean to be run."""

STAND_IN_CAMERAS = {
    "cube_plus": "Canon EOS 600D",
    "nus8-C1": "Canon EOS-1Ds Mark III",
    "nus8-Canon600D": "Canon EOS 600D",
    "nus8-Fuji": "Fujifilm X-T3",
    "nus8-NikonD5200": "Nikon D5300",
    "nus8-Olympus": "Canon EOS 5D Mark II",
    "nus8-Panasonic": "Panasonic DC-GX9",
    "nus8-Samsung": "Canon EOS 5D Mark II",
    "nus8-Sony": "Sony DSC-RX100M4",
}
"""The research photo sets pages name (Cube+ and the eight NUS-8 cameras; their photographs are not
part of ccjax), each with the embedded camera whose curves render its stand-in: the curves the
pages name for it (``--camera-for``), a same-maker stand-in, or the default world's camera where
ccjax has none."""


@dataclasses.dataclass(frozen=True)
class Block:
    """One fenced block of a page.

    Attributes:
        kind: ``"python"`` or ``"shell"``.
        code: what a reader pastes (for a console block, its commands without the ``$ ``).
        line: the line of its opening fence (1-based).
        not_run: the reason a ``<!-- not run: ... -->`` mark gives, or None.
    """

    kind: str
    code: str
    line: int
    not_run: str | None = None


def console_commands(text: str) -> str:
    """The commands of a console block: its ``$ `` lines, each continued by the lines after it
    while it ends with a backslash; every other line is output and left out.

    Arguments:
        text: the block's text.

    Returns:
        The commands, one per line (continuations kept as written).
    """
    commands, continuing = [], False
    for line in text.splitlines():
        if continuing:
            commands.append(line)
        elif line.startswith("$ "):
            commands.append(line[2:])
        else:
            continue
        continuing = line.endswith("\\")
    return "\n".join(commands) + ("\n" if commands else "")


def page_blocks(text: str) -> list[Block]:
    """The ```python and shell (```bash, ```sh, ```console) blocks of a Markdown page, in order.

    Arguments:
        text: the page.

    Returns:
        The blocks; other fences (```text, ```yaml ...) are output or file contents, not commands.

    Raises:
        ValueError: a fence is not closed.
    """
    lines = text.splitlines()
    blocks, index = [], 0
    while index < len(lines):
        opening = re.fullmatch(r"```(\w*)\s*", lines[index])
        if not opening:
            index += 1
            continue
        end = next((j for j in range(index + 1, len(lines)) if lines[j].strip() == "```"), None)
        if end is None:
            raise ValueError(f"page: the fence of line {index + 1} is not closed")
        language, body = opening.group(1), "\n".join(lines[index + 1 : end]) + "\n"
        if language == "python" or language in SHELLS:
            kind = "python" if language == "python" else "shell"
            code = console_commands(body) if language == "console" else body
            blocks.append(Block(kind, code, index + 1, _mark_before(lines, index)))
        index = end + 1
    return blocks


def _mark_before(lines: list[str], index: int) -> str | None:
    """The reason of a not-run mark in the lines just above line ``index`` (blank lines between
    allowed), or None."""
    above = index - 1
    while above >= 0 and not lines[above].strip():
        above -= 1
    start = above
    # A mark may span lines: walk up to the line that opens the comment.
    while start >= 0 and "<!--" not in lines[start] and lines[start].strip():
        start -= 1
    if above < 0 or start < 0 or not lines[above].rstrip().endswith("-->"):
        return None
    found = NOT_RUN.fullmatch(" ".join(line.strip() for line in lines[start : above + 1]))
    return found.group("reason") if found else None


def stand_in_sets(blocks: list[Block]) -> list[str]:
    """The research photo sets (``STAND_IN_CAMERAS``) that the run shell blocks name.

    Arguments:
        blocks: a page's blocks.

    Returns:
        The set names, sorted.
    """
    text = "\n".join(block.code for block in blocks if block.kind == "shell" and block.not_run is None)
    return sorted(name for name in STAND_IN_CAMERAS if re.search(rf"(?<![\w/-]){re.escape(name)}(?![\w-])", text))


def write_stand_in_sets(names: list[str], images: int = 6, size: int = 32) -> None:
    """Write each named set in the working folder as its stand-in: ``images`` Mondrians of
    ``size`` x ``size`` pixels rendered with highlights through the set's camera
    (``STAND_IN_CAMERAS``), 16-bit linear PNGs, with a ``groundtruth.csv`` of their lights.

    Arguments:
        names: set names (keys of ``STAND_IN_CAMERAS``).
        images: images per set (6: 3-fold training needs 4 training images a fold).
        size: their height and width in pixels.
    """
    import equinox as eqx
    import jax

    from ccjax import Camera, World, io
    from ccjax.scenes import sample_mondrians

    default = World.default()
    for seed, name in enumerate(names):
        # The default world's spectra seen through the set's camera: one world built, one program
        # compiled (a world per camera would select its lights and compile again, seconds each).
        world = eqx.tree_at(lambda w: w.camera, default, Camera.from_name(STAND_IN_CAMERAS[name]))
        drawn = sample_mondrians(jax.random.key(seed), world, images, height=size, width=size, specular=True)
        io.write_dataset(name, drawn.image, drawn.illuminant)
