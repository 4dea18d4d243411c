"""Print the degenerate-input sweep: every buildable label on zero, masked, single,
identical, scaled and one-channel scenes; exits 1 when any cell breaks the contract.

Usage: ``python benchmarks/degenerate.py [LABEL ...]`` (default: every label, see
:func:`ccjax.experiments.degenerate.sweep_labels`).
"""

import sys

from ccjax.experiments.degenerate import degenerate_sweep
from ccjax.world import World


def main(argv: list[str]) -> int:
    """Run the sweep on the default world and print its table.

    Arguments:
        argv: labels to sweep (empty: all).

    Returns:
        The exit status: 0 when every cell passes.
    """
    result = degenerate_sweep(
        World.default(), argv or None, progress=lambda label: print(f"... {label}", file=sys.stderr)
    )
    print(result.table())
    failures = result.failures()
    for row in failures:
        print(f"FAIL {row.label} / {row.case}: finite={row.finite} ok={row.ok} status={row.status}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
