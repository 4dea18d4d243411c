"""Scale-out primitives: the item axis (scenes, images, training examples) split over processes
started under ``jax.distributed`` and sharded over a device mesh (docs/training.md).

Two ways to spread a run, both built from these pieces:

* **a share per process**: each process takes :func:`process_share` of the items (it reads only
  those files, samples only those scenes), runs them on its own devices, and :func:`gather` pools
  the per-item results in item order on every process;
* **one global mesh**: :func:`item_mesh` spans every process's devices; each process puts its rows
  of a chunk onto it with :func:`shard_items` (after :func:`pad_items` to a multiple of the device
  count), one ``jit`` program runs on the whole chunk, and :func:`global_value` brings the sharded
  result back to every process as NumPy.

Data-parallel training needs no collective of its own: under ``jit``, the gradient of a mean loss
over a batch sharded with :func:`shard_items`, taken with respect to parameters put on the mesh
with :func:`replicate`, is already the gradient of the pooled batch (XLA inserts the sum across
devices and processes), replicated on every device.

With one process (no ``jax.distributed``) every function works the same: the share is every item,
:func:`gather` returns its input as NumPy.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = [
    "ITEMS",
    "distributed_environment",
    "gather",
    "global_value",
    "initialize_from_environment",
    "item_mesh",
    "item_sharding",
    "pad_items",
    "padded_count",
    "process_share",
    "replicate",
    "shard_items",
]

ITEMS = "items"
"""The mesh axis name of the item axis."""

# Launchers whose environment `jax.distributed.initialize()` reads by itself (JAX's cluster
# detection), as (variable that marks the launcher, variable holding its process count).
_CLUSTERS = (
    ("SLURM_JOB_ID", "SLURM_NTASKS"),
    ("OMPI_MCA_orte_hnp_uri", "OMPI_COMM_WORLD_SIZE"),
)
# JAX's Slurm detection needs all of these; with one missing it does not recognise Slurm.
_SLURM = ("SLURM_JOB_ID", "SLURM_STEP_NODELIST", "SLURM_NTASKS", "SLURM_PROCID", "SLURM_LOCALID")


def _integer(environ: Mapping[str, str], name: str, low: int) -> int:
    text = environ[name]
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"{name}: expected an integer, got {text!r}") from None
    if value < low:
        raise ValueError(f"{name}: expected an integer >= {low}, got {value}")
    return value


def distributed_environment(environ: Mapping[str, str] | None = None) -> dict | None:
    """The ``jax.distributed.initialize`` arguments the environment asks for (pure: reads only
    ``environ``); see :func:`initialize_from_environment` for the variables.

    Arguments:
        environ: the environment (default ``os.environ``).

    Returns:
        The keyword arguments (``{}``: let JAX detect the launcher's own variables), or ``None``
        when the environment does not describe a multi-process run.

    Raises:
        ValueError: ``JAX_NUM_PROCESSES`` or ``JAX_PROCESS_ID`` is set without the other, or
            without ``JAX_COORDINATOR_ADDRESS``, or is not an integer in range.
    """
    env = os.environ if environ is None else environ
    address = env.get("JAX_COORDINATOR_ADDRESS", "").strip()
    given = [name for name in ("JAX_NUM_PROCESSES", "JAX_PROCESS_ID") if env.get(name, "").strip()]
    if given and (len(given) < 2 or not address):
        missing = [n for n in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID") if not env.get(n)]
        raise ValueError(f"{given[0]}: set together with {', '.join(missing)} (a multi-process run needs all three)")
    if given:
        count = _integer(env, "JAX_NUM_PROCESSES", 1)
        index = _integer(env, "JAX_PROCESS_ID", 0)
        if index >= count:
            raise ValueError(f"JAX_PROCESS_ID: expected an integer below JAX_NUM_PROCESSES ({count}), got {index}")
        return {"coordinator_address": address, "num_processes": count, "process_id": index}
    if address:
        return {"coordinator_address": address}  # the rest from the launcher (JAX's detection)
    for marker, count_name in _CLUSTERS:
        if marker in env and count_name in env:
            if marker == "SLURM_JOB_ID" and not all(name in env for name in _SLURM):
                continue
            if _integer(env, count_name, 1) > 1:
                return {}
    return None


def initialize_from_environment(environ: Mapping[str, str] | None = None) -> bool:
    """Start ``jax.distributed`` when the environment describes a multi-process run; else nothing.

    Call it first thing, before any JAX computation (JAX refuses to initialise after one). It is
    what ``ccjax compare``, ``evaluate`` and ``train`` call, so starting the same command in every
    process with these variables spreads the run:

    * ``JAX_COORDINATOR_ADDRESS`` (``host:port`` of process 0, reachable from every process),
      ``JAX_NUM_PROCESSES`` and ``JAX_PROCESS_ID`` (``0 .. N-1``): an explicit launch, e.g.
      ``JAX_COORDINATOR_ADDRESS=localhost:12345 JAX_NUM_PROCESSES=2 JAX_PROCESS_ID=0 ccjax ...``;
    * ``JAX_COORDINATOR_ADDRESS`` alone: the process count and index come from the launcher
      (JAX's own detection);
    * a Slurm job step (``srun``; ``SLURM_JOB_ID``, ``SLURM_STEP_NODELIST``, ``SLURM_NTASKS`` > 1,
      ``SLURM_PROCID``, ``SLURM_LOCALID``) or Open MPI (``mpirun``; ``OMPI_MCA_orte_hnp_uri``,
      ``OMPI_COMM_WORLD_SIZE`` > 1): ``jax.distributed.initialize()`` with JAX's detection.

    ``JAX_LOCAL_DEVICE_IDS`` (read by JAX) restricts a process to some of its host's devices. Other
    launchers JAX detects (Cloud TPU pods, Kubernetes, mpi4py) are not guessed from the
    environment (a single process in a Kubernetes pod looks the same): call
    ``jax.distributed.initialize()`` yourself there. Cross-process collectives on CPU use gloo
    (``jax_cpu_collectives_implementation``; a value set through
    ``JAX_CPU_COLLECTIVES_IMPLEMENTATION`` is kept).

    Arguments:
        environ: the environment (default ``os.environ``).

    Returns:
        True when JAX runs distributed (now or already), False for a single process.

    Raises:
        ValueError: an incomplete or malformed set of variables (:func:`distributed_environment`).
    """
    if jax.distributed.is_initialized():
        return True
    arguments = distributed_environment(environ)
    if arguments is None:
        return False
    env = os.environ if environ is None else environ
    if not env.get("JAX_CPU_COLLECTIVES_IMPLEMENTATION"):
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(**arguments)
    return True


def item_mesh(devices=None) -> Mesh:
    """A one-axis mesh (axis :data:`ITEMS`) over ``devices``, ordered by process then device id,
    so a process's rows of the item axis are one contiguous block, in process order.

    Arguments:
        devices: the devices (default: every process's, ``jax.devices()``).

    Returns:
        The ``jax.sharding.Mesh``.
    """
    chosen = list(jax.devices() if devices is None else devices)
    if not chosen:
        raise ValueError("devices: empty")
    chosen.sort(key=lambda device: (device.process_index, device.id))
    return Mesh(np.array(chosen), (ITEMS,))


def item_sharding(mesh: Mesh) -> NamedSharding:
    """The sharding of an array split on its leading (item) axis over ``mesh``'s one axis.

    Arguments:
        mesh: a one-axis mesh (:func:`item_mesh`).

    Returns:
        ``NamedSharding(mesh, PartitionSpec(axis))``.
    """
    if len(mesh.axis_names) != 1:
        raise ValueError(f"mesh: expected one axis, got {mesh.axis_names}")
    return NamedSharding(mesh, PartitionSpec(mesh.axis_names[0]))


def process_share(n_items: int, *, process_index: int | None = None, process_count: int | None = None) -> slice:
    """The contiguous block of item indices this process owns: blocks of ``ceil(n / processes)``
    items in process order (the last ones may be short or empty).

    Arguments:
        n_items: number of items.
        process_index, process_count: the process and the count (default ``jax.process_index()``
            and ``jax.process_count()``).

    Returns:
        A ``slice`` of ``range(n_items)`` (single process: all of it).
    """
    count = jax.process_count() if process_count is None else process_count
    index = jax.process_index() if process_index is None else process_index
    if isinstance(n_items, bool) or not isinstance(n_items, (int, np.integer)) or n_items < 0:
        raise ValueError(f"n_items: expected a non-negative integer, got {n_items!r}")
    if not 0 <= index < count:
        raise ValueError(f"process_index: expected an integer in [0, {count}), got {index}")
    n = int(n_items)
    block = math.ceil(n / count)
    return slice(min(index * block, n), min((index + 1) * block, n))


def padded_count(n_items: int, multiple: int) -> int:
    """``n_items`` rounded up to a multiple of ``multiple`` (at least one multiple).

    Arguments:
        n_items: number of items.
        multiple: e.g. the mesh's device count (``mesh.devices.size``).

    Returns:
        The padded count.
    """
    if multiple < 1:
        raise ValueError(f"multiple: expected a positive integer, got {multiple}")
    return max(1, math.ceil(n_items / multiple)) * multiple


def _leading(leaves: list, name: str) -> int:
    lengths = {int(np.shape(leaf)[0]) if np.ndim(leaf) else -1 for leaf in leaves}
    if -1 in lengths or len(lengths) > 1:
        raise ValueError(f"{name}: expected arrays with one leading (item) axis of one length, got {sorted(lengths)}")
    return lengths.pop() if lengths else 0


def pad_items(tree, size: int):
    """Pad every array of ``tree`` on its leading axis to ``size`` items by repeating the last item
    (zeros when there is none), so padded items are valid inputs; trim results with ``[:n]`` or
    the mask.

    Arguments:
        tree: a PyTree of arrays sharing their leading length ``n <= size``.
        size: the padded length (:func:`padded_count`).

    Returns:
        ``(padded tree, mask (size,))``, mask True on the ``n`` real items.
    """
    leaves, treedef = jax.tree.flatten(tree)
    n = _leading(leaves, "tree")
    if n > size:
        raise ValueError(f"size: expected at least the {n} items, got {size}")

    def pad(leaf):
        xp = jnp if isinstance(leaf, jax.Array) else np
        if n == 0:
            return xp.zeros((size, *np.shape(leaf)[1:]), leaf.dtype)
        return xp.concatenate([leaf, xp.repeat(leaf[-1:], size - n, axis=0)])

    return jax.tree.unflatten(treedef, [pad(leaf) for leaf in leaves]), np.arange(size) < n


def shard_items(tree, mesh: Mesh):
    """Put this process's rows of a batch onto ``mesh``, split on the leading (item) axis.

    On a mesh of this process's devices the rows are the whole batch (``jax.device_put``); on a
    mesh spanning processes (:func:`item_mesh` after :func:`initialize_from_environment`) each
    process passes its own block (every process the same number of rows, e.g. its
    :func:`process_share` of a chunk whose size is a multiple of the device count) and the result
    is the global batch, blocks in process order (``jax.make_array_from_process_local_data``).

    Arguments:
        tree: a PyTree of arrays (PRNG key arrays too) sharing their leading length, a multiple of
            the number of this process's devices in ``mesh`` (:func:`pad_items`).
        mesh: a one-axis mesh.

    Returns:
        The tree of sharded JAX arrays.
    """
    sharding = item_sharding(mesh)
    leaves, treedef = jax.tree.flatten(tree)
    n = _leading(leaves, "tree")
    local = [device for device in mesh.devices.flat if device.process_index == jax.process_index()]
    if not local or n % len(local):
        raise ValueError(f"tree: {n} items do not split evenly over this process's {len(local)} devices of the mesh")
    spans_processes = len(local) < mesh.devices.size

    def put(leaf):
        if jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            return jax.random.wrap_key_data(put(jax.random.key_data(leaf)), impl=jax.random.key_impl(leaf))
        if spans_processes:
            return jax.make_array_from_process_local_data(sharding, np.asarray(leaf))
        return jax.device_put(leaf, sharding)

    return jax.tree.unflatten(treedef, [put(leaf) for leaf in leaves])


def replicate(tree, mesh: Mesh):
    """Put the same value (parameters, optimiser state, keys) on every device of ``mesh``; every
    process must pass the same value.

    Arguments:
        tree: a PyTree of arrays.
        mesh: the mesh.

    Returns:
        The tree of fully replicated JAX arrays.
    """
    sharding = NamedSharding(mesh, PartitionSpec())

    def put(leaf):
        if isinstance(leaf, jax.Array) and jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            return jax.random.wrap_key_data(put(jax.random.key_data(leaf)), impl=jax.random.key_impl(leaf))
        return jax.device_put(np.asarray(leaf) if mesh.devices.size > len(mesh.local_devices) else leaf, sharding)

    return jax.tree.map(put, tree)


def global_value(tree):
    """The whole value of (possibly sharded, multi-process) arrays as NumPy, on every process.

    Arguments:
        tree: a PyTree of arrays (e.g. per-item results of a program run on :func:`shard_items`
            input).

    Returns:
        The tree of NumPy arrays.
    """

    def fetch(leaf):
        if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable and not leaf.is_fully_replicated:
            return np.asarray(multihost_utils.process_allgather(leaf, tiled=True))
        return np.asarray(leaf)

    return jax.tree.map(fetch, tree)


def _as_bytes(leaf: np.ndarray, rows: int) -> np.ndarray:
    """``(rows, bytes per item)`` uint8 view of an array padded with zero items to ``rows``."""
    flat = np.ascontiguousarray(leaf).reshape(leaf.shape[0], -1).view(np.uint8)
    return np.concatenate([flat, np.zeros((rows - flat.shape[0], flat.shape[1]), np.uint8)])


def gather(local):
    """Concatenate every process's per-item arrays in process order, on every process.

    The arrays travel as bytes (any dtype, exactly; no float64 narrowed by JAX's x64 setting),
    each process's block padded to the longest and trimmed, so blocks may differ in length (a
    :func:`process_share` whose last block is short or empty).

    Arguments:
        local: a PyTree of NumPy or JAX arrays (numbers or booleans) sharing their leading
            (item) length; every process passes the same structure, dtypes and trailing shapes.

    Returns:
        The tree of NumPy arrays over every process's items (single process: ``local`` as NumPy).

    Raises:
        ValueError: leaves of different leading lengths or of a non-numeric dtype, or processes
            whose trees differ in structure, dtype or trailing shape.
    """
    leaves, treedef = jax.tree.flatten(local)
    arrays = [np.asarray(leaf) for leaf in leaves]
    n = _leading(arrays, "local")
    for array in arrays:
        if not (np.issubdtype(array.dtype, np.number) or array.dtype == np.bool_):
            raise ValueError(f"local: expected numeric or boolean arrays, got dtype {array.dtype}")
    if jax.process_count() == 1:
        return jax.tree.unflatten(treedef, arrays)
    layout = repr((treedef, [(a.dtype.str, a.shape[1:]) for a in arrays])).encode()
    header = np.array([n, int.from_bytes(hashlib.sha256(layout).digest()[:7], "little")], np.int64)
    headers = np.asarray(multihost_utils.process_allgather(header.view(np.uint8))).view(np.int64)
    if len(set(headers[:, 1].tolist())) > 1:
        raise ValueError("local: the processes' arrays differ in structure, dtype or trailing shape")
    counts = headers[:, 0].tolist()
    rows = max(1, max(counts))
    blocks = multihost_utils.process_allgather([_as_bytes(a, rows) for a in arrays])
    out = []
    for array, block in zip(arrays, blocks):
        block = np.asarray(block)
        data = np.concatenate([block[p, :count] for p, count in enumerate(counts)])
        out.append(data.view(array.dtype).reshape(sum(counts), *array.shape[1:]))
    return jax.tree.unflatten(treedef, out)
