"""A fork server for the kill tests: one process imports the ``ccjax`` command line (and JAX, whose
backend it never starts, so forking is safe) once, then forks one child per request that runs
:func:`ccjax.cli.main` as the ``ccjax`` command would. A trial then costs the command's own work,
not a fresh interpreter importing JAX.

Protocol (one JSON object per line): the test writes ``{"argv": [...], "cwd": ..., "stdout": ...,
"stderr": ...}``; the server answers ``{"pid": PID}`` at once and ``{"pid": PID, "status": CODE}``
when the child has ended (``CODE`` is the exit code, or minus the signal that killed it), with
``"maxrss_kb"``: the child's peak resident memory from ``os.wait4`` (on Linux it counts the
pages it shares with the server too, so it is an upper bound of what the command alone needs).

Run as ``python fork_server.py``; it stops at the end of its input.
"""

from __future__ import annotations

import json
import os
import sys


def preload() -> None:
    """Import what ``ccjax correct`` uses, without starting JAX's backend (threads must not exist
    when the server forks)."""
    import jax  # noqa: F401
    import tqdm.auto  # noqa: F401

    import ccjax.cli
    import ccjax.cli.photos
    import ccjax.correction
    import ccjax.io
    import ccjax.preprocessing

    for group in ccjax.cli.groups():  # the parser's modules
        assert group.COMMANDS


def child(request: dict) -> None:
    """Run one command in the forked child and leave with its exit code (never returns)."""
    code = 1
    try:
        os.chdir(request["cwd"])
        for name, descriptor in (("stdout", 1), ("stderr", 2)):
            handle = os.open(request[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(handle, descriptor)
            os.close(handle)
        from ccjax import cli

        code = cli.main(request["argv"])
    except SystemExit as exit:  # argparse
        code = exit.code if isinstance(exit.code, int) else 1
    except BaseException:
        import traceback

        traceback.print_exc()  # what the command's own tracebacks would show
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def serve() -> None:
    preload()
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            child(request)
        print(json.dumps({"pid": pid}), flush=True)
        _, status, usage = os.wait4(pid, 0)
        code = os.waitstatus_to_exitcode(status)
        print(json.dumps({"pid": pid, "status": code, "maxrss_kb": usage.ru_maxrss}), flush=True)


if __name__ == "__main__":
    serve()
