"""Networks of one architecture trained as one batched pass (issue 54 item 4): each gets what it gets
alone, to float tolerance, on the CPU."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hybrid.learning import LearnedModel, TrainingSettings, fit_together, train, train_together
from hybrid.networks import make_network
from physics.data import DataError


@pytest.fixture(scope="module")
def windows():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(600, 10, 2)).astype(np.float32)
    y = (np.sin(x[:, -1, :1]) + 0.3 * x[:, 0, 1:] * x[:, -2, :1]).astype(np.float32)
    return x, y


def _built(net, seed):
    torch.manual_seed(seed)
    return net.build(2, 1)


@pytest.mark.parametrize("validation, patience, epochs, lr", [(0.0, None, 3, 1e-3), (0.25, 1, 8, 1e-2)])
def test_each_network_of_the_pass_ends_where_it_would_alone(windows, validation, patience, epochs, lr):
    x, y = windows
    net = make_network("fnn-hib", buffer=10, hidden=(32, 32))
    settings = [TrainingSettings(epochs=epochs, batch_size=16, lr=lr, seed=s, validation=validation,
                                 patience=patience, progress=False, threads=1) for s in (0, 1, 2)]
    torch.set_num_threads(1)
    alone = [_built(net, s.seed) for s in settings]
    histories = [train(m, x, y, s) for m, s in zip(alone, settings)]
    together = [_built(net, s.seed) for s in settings]
    batched = train_together(together, x, y, settings)
    probe = torch.from_numpy(x[:200])
    for a, b, ha, hb in zip(alone, together, histories, batched):
        np.testing.assert_allclose(b(probe).detach().numpy(), a(probe).detach().numpy(), rtol=0, atol=1e-5)
        np.testing.assert_allclose(hb.train_loss, ha.train_loss, rtol=1e-5)
        np.testing.assert_allclose(hb.val_loss, ha.val_loss, rtol=1e-5)
        assert (hb.best_epoch, hb.stopped_early, hb.n_train, hb.n_val) == \
            (ha.best_epoch, ha.stopped_early, ha.n_train, ha.n_val)
    if patience is not None:  # the seeds stop early at different epochs (4, 6 and none), each as alone
        assert len({h.epochs_run for h in batched}) == 3 and any(h.stopped_early for h in batched)
    # the seeds are different networks, not one network three times
    assert not np.allclose(together[0](probe).detach().numpy(), together[1](probe).detach().numpy())


def test_fit_together_gives_each_estimator_its_own_fit(windows):
    from physics.virtual import paper_protocol

    split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    make = [LearnedModel(make_network("fnn-hib", buffer=10), training=TrainingSettings(
        epochs=2, seed=s, progress=False, threads=1)) for s in (0, 1)]
    fitted = fit_together(make, split.train)
    for model, seed in zip(fitted, (0, 1)):
        alone = LearnedModel(make_network("fnn-hib", buffer=10), training=TrainingSettings(
            epochs=2, seed=seed, progress=False, threads=1)).fit(split.train)
        np.testing.assert_allclose(model.predict(split.test[0]), alone.predict(split.test[0]), rtol=0, atol=1e-4)
        assert model.history_.epochs_run == alone.history_.epochs_run == 2


def test_networks_vmap_cannot_batch_train_one_after_another_with_the_same_results(windows):
    x, y = windows
    net = make_network("lstm", hidden=8, layers=1, seq_len=10)
    settings = [TrainingSettings(epochs=1, batch_size=32, seed=s, progress=False, threads=1) for s in (0, 1)]
    alone = [_built(net, s.seed) for s in settings]
    for m, s in zip(alone, settings):
        train(m, x, y, s)
    together = [_built(net, s.seed) for s in settings]
    train_together(together, x, y, settings)
    probe = torch.from_numpy(x[:50])
    for a, b in zip(alone, together):
        np.testing.assert_allclose(b(probe).detach().numpy(), a(probe).detach().numpy(), rtol=0, atol=1e-5)


def test_what_cannot_share_a_pass_is_refused(windows):
    x, y = windows
    net = make_network("fnn-hib", buffer=10)
    with pytest.raises(DataError, match="differ only in their seed"):
        train_together([_built(net, 0), _built(net, 1)], x, y,
                       [TrainingSettings(lr=1e-3, progress=False), TrainingSettings(lr=1e-2, seed=1, progress=False)])
    other = make_network("fnn-hib", buffer=10, hidden=(8,))
    with pytest.raises(DataError, match="one architecture"):
        train_together([_built(net, 0), _built(other, 1)], x, y,
                       [TrainingSettings(progress=False), TrainingSettings(seed=1, progress=False)])
    with pytest.raises(DataError, match="one TrainingSettings per module"):
        train_together([_built(net, 0)], x, y, [])
    with pytest.raises(DataError, match="differ only in their training seed"):
        fit_together([LearnedModel(make_network("fnn-hib", buffer=10)), LearnedModel(make_network("fnn"))],
                      [__import__("physics.virtual", fromlist=["paper_protocol"]).paper_protocol(
                          frequencies=(0.5,), tests=(0.45,), baselines=("mid",)).train[0]])
