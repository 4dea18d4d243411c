"""Commands that only load the estimators and draw scenes do not import SciPy's optimize, spatial or
ndimage modules (about half a second of every ``ccjax estimate``): the fits that use them import
them on use."""

from __future__ import annotations

import subprocess
import sys

SLOW_TO_IMPORT = ("scipy.optimize", "scipy.spatial", "scipy.ndimage")


def test_loading_the_estimators_and_scenes_imports_no_slow_scipy_module():
    code = (
        "import sys\n"
        "import ccjax.runs.engine, ccjax.scenes, ccjax.estimators.gamut, ccjax.estimators.correlation\n"
        f"print(sorted(name for name in {SLOW_TO_IMPORT!r} if name in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


def test_the_check_sees_an_import():
    # The same check reports a module once it is imported, so the test above can fail.
    code = f"import sys, scipy.spatial\nprint(sorted(n for n in {SLOW_TO_IMPORT!r} if n in sys.modules))\n"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "scipy.spatial" in done.stdout
