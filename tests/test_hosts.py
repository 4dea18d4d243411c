"""The scale-out primitives of ``ccjax.runs.hosts`` in one process: the shares, padding and
environment rules against their definitions; sharding on a one-device mesh. (Two processes and four
devices: tests/test_distributed.py.)"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ccjax.runs import hosts


@pytest.mark.parametrize("n_items", [0, 1, 5, 7, 8, 51])
@pytest.mark.parametrize("count", [1, 2, 3, 4])
def test_process_share_blocks(n_items, count):
    shares = [hosts.process_share(n_items, process_index=i, process_count=count) for i in range(count)]
    block = -(-n_items // count)  # ceil
    covered = [i for share in shares for i in range(n_items)[share]]
    assert covered == list(range(n_items))  # disjoint, complete, in process order
    sizes = [share.stop - share.start for share in shares]
    assert all(size == block for size in sizes[: n_items // block if block else 0])
    assert all(0 <= size <= block for size in sizes)


def test_process_share_single_process_is_everything():
    assert hosts.process_share(9) == slice(0, 9)
    with pytest.raises(ValueError, match="n_items"):
        hosts.process_share(-1)
    with pytest.raises(ValueError, match="process_index"):
        hosts.process_share(4, process_index=2, process_count=2)


def test_padded_count_and_pad_items():
    assert [hosts.padded_count(n, 4) for n in (0, 1, 4, 5, 8)] == [4, 4, 4, 8, 8]
    x = np.arange(6.0).reshape(3, 2)
    keys = jax.random.split(jax.random.key(0), 3)
    (padded, padded_keys), mask = hosts.pad_items((x, keys), 4)
    assert np.array_equal(padded, [[0, 1], [2, 3], [4, 5], [4, 5]])  # the last item repeated
    assert np.array_equal(jax.random.key_data(padded_keys[3]), jax.random.key_data(keys[2]))
    assert mask.tolist() == [True, True, True, False]
    empty, mask = hosts.pad_items(np.zeros((0, 3), np.float32), 2)
    assert empty.shape == (2, 3) and not mask.any()
    with pytest.raises(ValueError, match="size"):
        hosts.pad_items(x, 2)
    with pytest.raises(ValueError, match="tree"):
        hosts.pad_items((x, np.zeros(2)), 4)


def test_distributed_environment_rules():
    explicit = {"JAX_COORDINATOR_ADDRESS": "host:1234", "JAX_NUM_PROCESSES": "4", "JAX_PROCESS_ID": "3"}
    assert hosts.distributed_environment(explicit) == {
        "coordinator_address": "host:1234",
        "num_processes": 4,
        "process_id": 3,
    }
    assert hosts.distributed_environment({}) is None
    assert hosts.distributed_environment({"JAX_COORDINATOR_ADDRESS": "h:1"}) == {"coordinator_address": "h:1"}
    slurm = {"SLURM_JOB_ID": "7", "SLURM_STEP_NODELIST": "n1", "SLURM_PROCID": "0", "SLURM_LOCALID": "0"}
    assert hosts.distributed_environment(slurm | {"SLURM_NTASKS": "1"}) is None  # one task: one process
    assert hosts.distributed_environment(slurm | {"SLURM_NTASKS": "2"}) == {}  # JAX detects the rest
    assert hosts.distributed_environment({"SLURM_JOB_ID": "7", "SLURM_NTASKS": "2"}) is None  # an allocation, no step
    mpi = {"OMPI_MCA_orte_hnp_uri": "1;tcp://10.0.0.1:1", "OMPI_COMM_WORLD_SIZE": "2"}
    assert hosts.distributed_environment(mpi) == {}
    assert hosts.distributed_environment({"KUBERNETES_SERVICE_HOST": "10.0.0.1"}) is None
    for broken, name in [
        ({"JAX_NUM_PROCESSES": "2"}, "JAX_NUM_PROCESSES"),
        (explicit | {"JAX_PROCESS_ID": "4"}, "JAX_PROCESS_ID"),
        (explicit | {"JAX_NUM_PROCESSES": "two"}, "JAX_NUM_PROCESSES"),
        ({k: v for k, v in explicit.items() if k != "JAX_COORDINATOR_ADDRESS"}, "JAX_COORDINATOR_ADDRESS"),
    ]:
        with pytest.raises(ValueError, match=name):
            hosts.distributed_environment(broken)


def test_initialize_without_environment_is_a_no_op():
    assert hosts.initialize_from_environment({}) is False
    assert jax.process_count() == 1


def test_gather_in_one_process_keeps_dtypes():
    local = {"error": np.array([1.5, 2.5], np.float64), "ok": jnp.array([True, False]), "n": np.arange(2)}
    pooled = hosts.gather(local)
    assert pooled["error"].dtype == np.float64 and np.array_equal(pooled["error"], local["error"])
    assert pooled["ok"].tolist() == [True, False] and isinstance(pooled["ok"], np.ndarray)
    with pytest.raises(ValueError, match="local"):
        hosts.gather({"a": np.zeros(2), "b": np.zeros(3)})
    with pytest.raises(ValueError, match="dtype"):
        hosts.gather(np.array(["a", "b"]))


def test_shard_items_on_one_device():
    mesh = hosts.item_mesh()
    assert mesh.axis_names == ("items",) and mesh.devices.size == len(jax.devices())
    x = np.arange(8.0, dtype=np.float32).reshape(4, 2)
    keys = jax.random.split(jax.random.key(1), 4)
    sharded_x, sharded_keys = hosts.shard_items((x, keys), mesh)
    assert sharded_x.sharding.is_equivalent_to(hosts.item_sharding(mesh), 2)
    assert np.array_equal(hosts.global_value(sharded_x), x)
    draws = jax.jit(jax.vmap(lambda k: jax.random.uniform(k)))(sharded_keys)
    assert np.array_equal(np.asarray(draws), np.asarray(jax.vmap(lambda k: jax.random.uniform(k))(keys)))
    replicated = hosts.replicate({"w": jnp.ones(3)}, mesh)
    assert replicated["w"].is_fully_replicated
    with pytest.raises(ValueError, match="mesh"):
        hosts.item_sharding(jax.sharding.Mesh(np.array(jax.devices()[:1]).reshape(1, 1), ("a", "b")))
