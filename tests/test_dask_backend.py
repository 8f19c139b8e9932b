"""Sweeps through joblib's dask backend (for users with a dask.distributed cluster)."""

import pandas as pd
import pytest

import sknarx.rotor as R

distributed = pytest.importorskip("distributed")


def test_sweep_on_a_dask_cluster_equals_local_sweep():
    from joblib import parallel_config

    sim = R.RotorBearingSimulator()
    kw = dict(fs=500.0, n_samples=200, settle=0.2, progress=False)
    local = sim.sweep([100.0, 150.0, 200.0], **kw)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster), parallel_config(backend="dask"):
        remote = sim.sweep([100.0, 150.0, 200.0], n_jobs=2, **kw)
    pd.testing.assert_frame_equal(local, remote)
