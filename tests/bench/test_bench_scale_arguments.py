"""`bench_scale` refuses a run it cannot measure before it starts any server, naming the flag."""

from __future__ import annotations

import pytest

from bench import bench_scale
from bench.bench_scale import main


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--components=3"], "--components: 3 components"),
        (["--robots=1000,10k"], "--robots: expected comma-separated whole numbers, got '1000,10k'"),
        (["--robots=0"], "--robots: each must be at least 1, got 0"),
        (["--workers=1,0"], "--workers: each must be at least 1, got 0"),
        (["--workers=65"], "--workers: each must be at most 64, got 65"),
        (["--rate=0"], "--rate: must be positive, got 0.0"),
        (["--trouble-share=1.5"], "--trouble-share: expected a share from 0 to 1, got 1.5"),
        (["--down-seconds=-1"], "--down-seconds: must not be negative, got -1.0"),
        (["--seconds=0"], "--seconds: must be positive, got 0.0"),
        (["--scrape-interval=0"], "--scrape-interval: must be at least 1 s, got 0"),
        (["--rules"], "--rules: needs --prometheus-seconds"),
        (["--floor-pieces"], "--floor-pieces: needs --prometheus-seconds"),
        (["--head-start=-0.5"], "--head-start: must be a finite number of seconds, not negative, got -0.5"),
        (["--head-start=nan"], "--head-start: must be a finite number of seconds, not negative, got nan"),
        (["--floor", "--transport=dds"], "--floor: its counting subscriber hears the fleet through"),
        (["--dds-shared-topic"], "--dds-shared-topic: needs --transport dds"),
        (["--prometheus-agent"], "--prometheus-agent: needs --prometheus-seconds"),
        (["--shards=0"], "--shards: must be from 1 to 8, got 0"),
        (["--shards=9"], "--shards: must be from 1 to 8, got 9"),
        (["--icinga2=0"], "--icinga2: the push's interval must be positive, got 0.0"),
        (["--icinga2", "--shards=2"], "--icinga2: with one exporter only"),
    ],
)
def test_a_run_that_cannot_be_measured_is_refused_with_the_flag_named(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def run(*_: object, **__: object) -> None:
        raise AssertionError("a run was started")  # not a minute of servers in the quick tests

    monkeypatch.setattr(bench_scale, "run", run)
    with pytest.raises(SystemExit) as refused:
        main(arguments)
    assert refused.value.code == 2
    assert message in capsys.readouterr().err
