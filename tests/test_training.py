"""ccjax.training: learnable parameters, the Adam loop (it reduces the loss, touches only the
learnable leaves, keeps the best held-out model), fold assignment, cross-validation that never
trains on the scored fold, model files and ``ccjax train``."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from traces import count_traces, record_traces

from ccjax import io, scenes, training
from ccjax.estimators import registry
from ccjax.estimators.correlation import ColourByCorrelation
from ccjax.runs import store

LABEL = "C-by-C-MMSE"


@pytest.fixture(scope="module")
def start(default_world):
    return store.fit(LABEL, default_world)


@pytest.fixture(scope="module")
def image_set(tmp_path_factory, default_world):
    images = scenes.sample_mondrians(jax.random.key(3), default_world, 24, height=32, width=32, n_patches=8)
    folder = tmp_path_factory.mktemp("training") / "images"
    truth = io.write_dataset(folder, np.asarray(images.image), np.asarray(images.illuminant))
    return folder, truth


@pytest.fixture(scope="module")
def examples(image_set, start):
    folder, truth = image_set
    return training.load_examples(folder, truth, start.input_kind)


def test_learnable_selects_the_matrix_only(start, default_world):
    spec = training.learnable(start)
    assert spec.log_probability is True
    assert spec.illuminant_rg is False and spec.fallback is False
    assert training.learnable(registry.fit("grey-edge-1-6-2", default_world)).p is True
    with pytest.raises(ValueError, match="no learnable parameters"):
        training.learnable(registry.fit("GW", default_world))


def test_examples_match_the_files(examples, image_set):
    _, truth = image_set
    assert len(examples) == 24 and examples.x.shape[0] == 24 and examples.x.shape[-1] == 3
    assert examples.names == tuple(io.read_ground_truth(truth))
    rows = io.read_ground_truth(truth)
    np.testing.assert_allclose(examples.illuminant, np.stack(list(rows.values())), rtol=1e-6)


def test_adam_reduces_the_loss_and_touches_only_learnable_leaves(start, examples, caplog):
    record_traces(caplog)
    schedule = training.Schedule(epochs=4, batch_size=8, learning_rate=0.05, patience=4, surfaces=None, relight=0.0)
    model, log = training.fit_to_examples(start, examples, schedule, validation=examples, progress=False)
    # The step is compiled once (at most: an earlier test may have compiled it) for every step of
    # the fit and for a fit at another rate, epochs and seed (values, not the step's program).
    other = dataclasses.replace(schedule, epochs=1, learning_rate=0.01, seed=1)
    training.fit_to_examples(start, examples, other, validation=examples, progress=False)
    assert count_traces(caplog, "_step") <= 1
    # Fixed data (no subsets, no relighting), validation = training: gradient descent must lower it.
    assert log.train_loss[-1] < log.train_loss[0]
    assert min(log.heldout_median) <= log.initial_median
    assert isinstance(model, ColourByCorrelation) and isinstance(start, ColourByCorrelation)
    assert not np.array_equal(model.log_probability, start.log_probability)
    np.testing.assert_array_equal(model.illuminant_rg, start.illuminant_rg)
    np.testing.assert_array_equal(model.fallback, start.fallback)
    # The returned model is the best epoch's (or the start when none was better).
    errors = training.angular_errors(model, examples)
    best = log.heldout_median[log.best_epoch - 1] if log.best_epoch else log.initial_median
    assert float(np.median(errors)) == pytest.approx(best, rel=1e-5)


def test_subsample_keeps_valid_surfaces_first():
    x = jnp.arange(2 * 6 * 3, dtype=jnp.float32).reshape(2, 6, 3)
    mask = jnp.asarray([[True, False, True, False, True, False], [False] * 5 + [True]])
    sub_x, sub_mask = training.subsample(jax.random.key(0), x, mask, 3)
    np.testing.assert_array_equal(sub_mask, [[True, True, True], [True, False, False]])
    assert sorted(np.asarray(sub_x[0, :, 0]).tolist()) == [0.0, 6.0, 12.0]
    assert float(sub_x[1, 0, 0]) == 33.0  # x[b, p, 0] = 3 (6 b + p)


def test_assign_folds(tmp_path):
    names = [f"im{i}" for i in range(10)]
    folds = training.assign_folds(names, 3, seed=1)
    np.testing.assert_array_equal(folds, training.assign_folds(names, 3, seed=1))
    assert sorted(np.bincount(folds).tolist()) == [3, 3, 4]
    csv = tmp_path / "gt.csv"
    csv.write_text("image,r,g,b,fold\n" + "".join(f"im{i},1,1,1,{i % 2 + 1}\n" for i in range(10)))
    given = training.read_folds(csv)
    assert given == {f"im{i}": i % 2 + 1 for i in range(10)}
    np.testing.assert_array_equal(training.assign_folds(names, 2, given=given), [i % 2 for i in range(10)])
    with pytest.raises(ValueError, match="distinct folds"):
        training.assign_folds(names, 3, given=given)
    with pytest.raises(ValueError, match="folds: expected an integer >= 2"):
        training.assign_folds(names, 1)
    (tmp_path / "plain.csv").write_text("image,r,g,b\nim0,1,1,1\n")
    assert training.read_folds(tmp_path / "plain.csv") is None
    (tmp_path / "bad.csv").write_text("image,r,g,b,fold\nim0,1,1,1,x\n")
    with pytest.raises(ValueError, match="line 2: fold must be an integer"):
        training.read_folds(tmp_path / "bad.csv")


def test_cross_validation_never_trains_on_the_scored_fold(start, examples, tmp_path):
    folds = training.assign_folds(examples.names, 2, seed=0)
    schedule = training.Schedule(epochs=1, batch_size=8, patience=1)
    result, models = training.cross_validate(start, examples, folds, schedule, method=LABEL, progress=False)
    assert len(result.folds) == 2 and len(models) == 2
    for fold in result.folds:
        test = [examples.names[i] for i in np.flatnonzero(folds == fold.fold)]
        assert fold.test_names == test
        assert fold.log.n_train + fold.log.n_heldout == len(examples) - len(test)
    assert sorted(n for f in result.folds for n in f.test_names) == sorted(examples.names)
    assert "pooled" in result.table()

    # Model files: the house format round trip.
    path = store.save_trained(tmp_path / "model.eqx", models[0], label=LABEL, camera="Canon EOS 5D Mark II")
    loaded = store.load_model(path)
    assert type(loaded) is type(models[0])
    for a, b in zip(
        jax.tree_util.tree_leaves(eqx.filter(loaded, eqx.is_array)),
        jax.tree_util.tree_leaves(eqx.filter(models[0], eqx.is_array)),
    ):
        np.testing.assert_array_equal(a, b)
    (tmp_path / "other.json").write_text('{"format": -1}')
    (tmp_path / "other.eqx").write_bytes(b"")
    with pytest.raises(ValueError, match="format"):
        store.load_model(tmp_path / "other.eqx")


def test_stop_on_mean_keeps_the_epoch_with_the_lowest_heldout_mean(examples, default_world):
    start = store.fit("log-chroma-mlp", default_world)
    schedule = training.Schedule(
        epochs=6, batch_size=8, learning_rate=0.02, patience=6, surfaces=None, relight=0.0, stop_on="mean"
    )
    model, log = training.fit_to_examples(start, examples, schedule, validation=examples, progress=False)
    # The kept model's held-out mean is the lowest of the start's and every epoch's, measured here.
    start_mean = float(np.mean(training.angular_errors(start, examples)))
    kept_mean = float(np.mean(training.angular_errors(model, examples)))
    assert kept_mean == pytest.approx(min([start_mean, *log.heldout_mean]), rel=1e-5)
    assert log.best_epoch == (1 + int(np.argmin(log.heldout_mean)) if min(log.heldout_mean) < start_mean else 0)


def test_default_schedule_is_the_family_one(start, default_world):
    net = store.fit("log-chroma-mlp", default_world)
    assert training.default_schedule(net) == training.LOG_CHROMA_SCHEDULE
    assert training.default_schedule(net, seed=3, epochs=7) == training.Schedule(
        learning_rate=training.LOG_CHROMA_SCHEDULE.learning_rate,
        epochs=7,
        patience=training.LOG_CHROMA_SCHEDULE.patience,
        stop_on="mean",
        seed=3,
    )
    assert training.default_schedule(start, seed=2) == training.Schedule(seed=2)


def test_schedule_checks():
    with pytest.raises(ValueError, match="stop_on"):
        training.Schedule(stop_on="max")
    with pytest.raises(ValueError, match="epochs"):
        training.Schedule(epochs=0)
    with pytest.raises(ValueError, match="relight"):
        training.Schedule(relight=2.0)
    with pytest.raises(ValueError, match="loss"):
        training.Schedule(loss="mapping_rgb")


@pytest.mark.slow
def test_train_command(image_set, tmp_path, capsys):
    from ccjax import cli

    folder, truth = image_set
    out = tmp_path / "cbc.eqx"
    status = cli.main(
        [
            "train",
            str(folder),
            "--ground-truth",
            str(truth),
            "--method",
            LABEL,
            "--folds",
            "2",
            "--epochs",
            "1",
            "--out",
            str(out),
            "--camera",
            "Canon EOS 5D Mark II",  # the default world's camera, which rendered the images
            "--no-progress",
        ]
    )
    assert status == 0
    text = capsys.readouterr().out
    assert "pooled" in text and "held-out median angular error" in text
    assert out.exists() and out.with_suffix(".json").exists()
    assert isinstance(store.load_model(out), type(store.fit(LABEL, __import__("ccjax").world.World.default())))


def test_estimate_with_a_model_file(start, examples, image_set, tmp_path, capsys):
    """``ccjax estimate IMAGE --model FILE`` loads the trained model (ccjax.load_model) and gives the
    in-memory trained model's estimate; the untrained start's differs."""
    import json

    import ccjax
    from ccjax import cli

    folder, _ = image_set
    schedule = training.Schedule(epochs=2, batch_size=8, learning_rate=0.2, surfaces=None, relight=0.0)
    model, _ = training.fit_to_examples(start, examples, schedule, validation=examples, progress=False)
    assert isinstance(model, ColourByCorrelation)
    model = eqx.tree_at(lambda m: m.log_probability, model, model.log_probability * 1.5)  # surely not the start
    path = store.save_trained(tmp_path / "cbc.eqx", model, label=LABEL, camera="Canon EOS 5D Mark II")
    assert isinstance(ccjax.load_model(path), type(start))
    image = folder / examples.names[0]
    assert cli.main(["estimate", str(image), "--model", str(path), "--json", "--no-progress"]) == 0
    printed = np.array(json.loads(capsys.readouterr().out)[0]["illuminant"])
    expected, _ = training.predict(model, examples.take([0]))
    untrained, _ = training.predict(start, examples.take([0]))
    # ccjax estimate prints lights with their largest channel 1.
    np.testing.assert_allclose(printed, expected[0] / np.max(expected[0]), rtol=1e-5)
    assert not np.allclose(printed, untrained[0] / np.max(untrained[0]), rtol=1e-3)
    assert cli.main(["estimate", str(image), "--no-progress"]) == 2
    assert "--method, --model: give exactly one" in capsys.readouterr().err
    assert cli.main(["estimate", str(image), "--model", str(tmp_path / "none.eqx")]) == 2
    assert "--model: no such model file" in capsys.readouterr().err
