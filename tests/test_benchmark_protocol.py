"""The claims benchmarks' shared protocol arguments: seed ranges and clear refusals."""

import argparse

import pytest

from benchmarks.protocol import add_protocol_args, protocol_seeds


def parse(*argv):
    parser = argparse.ArgumentParser()
    add_protocol_args(parser)
    return parser.parse_args(list(argv))


def test_defaults_are_the_protocol():
    args = parse()
    assert (args.episodes, args.seed_start, args.threads, args.no_record) == (200, 100_000, 1, False)
    seeds = protocol_seeds(args)
    assert seeds[0] == 100_000 and seeds[-1] == 100_199 and len(seeds) == 200


@pytest.mark.parametrize("argv, bad", [(["--episodes", "0"], "--episodes must be >= 1, got 0"),
                                       (["--threads", "0"], "--threads must be >= 1, got 0"),
                                       (["--seed-start", "-5"], "--seed-start must be >= 0, got -5")])
def test_bad_values_are_named(argv, bad):
    with pytest.raises(SystemExit, match=bad):
        protocol_seeds(parse(*argv))


def test_validation_range_is_flagged(capsys):
    assert protocol_seeds(parse("--seed-start", "200000", "--episodes", "3")) == [200000, 200001, 200002]
    assert "200000+ is validation" in capsys.readouterr().out


def test_t_estimate_matches_scipy():
    from scipy import stats

    from benchmarks.protocol import t_estimate

    values = [0.788, 0.793, 0.795]
    mean, lo, hi = t_estimate(values)
    ref = stats.t.interval(0.95, len(values) - 1, loc=sum(values) / 3, scale=stats.sem(values))
    assert mean == pytest.approx(0.792) and (lo, hi) == pytest.approx(ref)
    assert t_estimate([0.5]) == (0.5, 0.5, 0.5)  # one seed: no spread to estimate
