"""Smoke test of the ``endeff process`` throughput benchmark (numbers are not asserted)."""

from __future__ import annotations

import pytest

from tools.bench_process import bench_process


@pytest.mark.integration
def test_bench_process_reports_both_runs() -> None:
    result = bench_process(frames=3, bags=2)
    assert result['width'] == 640 and result['height'] == 480
    assert result['one_core']['frames'] == 3 and result['one_core']['errors'] == []
    assert result['n_processes']['frames'] == 6 and result['n_processes']['jobs'] == 2
    assert result['n_processes']['errors'] == []
    assert result['one_core']['fps'] > 0 and 'speedup' in result
