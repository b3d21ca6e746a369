"""The simulator's buffered noise: the Generator's own normals, in order, across block boundaries."""

import math

import numpy as np

from preland_app.sim.noise import GaussianStream, GaussMarkov


def test_a_gaussian_stream_gives_the_generators_normals_in_order_across_blocks():
    stream = GaussianStream(np.random.default_rng(7))
    values = [stream.next() for _ in range(5000)]
    reference = np.random.default_rng(7)
    expected = reference.standard_normal(4096).tolist() + reference.standard_normal(4096).tolist()[:904]
    assert values == expected


def test_two_streams_on_one_generator_draw_their_blocks_when_first_read():
    rng = np.random.default_rng(11)
    first, second = GaussianStream(rng), GaussianStream(rng)
    # The second stream is read first, so it holds the Generator's first block.
    assert second.next() == np.random.default_rng(11).standard_normal(4096)[0]
    reference = np.random.default_rng(11)
    reference.standard_normal(4096)
    assert first.next() == reference.standard_normal(4096)[0]


def test_a_gauss_markov_step_follows_its_exact_discretisation():
    process = GaussMarkov(sigma=0.5, tau_s=2.0, noise=GaussianStream(np.random.default_rng(3)))
    draws = np.random.default_rng(3).standard_normal(4096).tolist()
    value = 0.5 * draws[0]
    assert process.value == value
    a = math.exp(-0.01 / 2.0)
    for k in range(1, 200):
        value = a * value + 0.5 * math.sqrt(1.0 - a * a) * draws[k]
        assert process.step(0.01) == value
