"""Real measured data that ship with sknarx, with their licence and provenance.

The rotor data come from a Bently Nevada RK-4 two-disk rotor kit (M. Nouioua, rotor unbalance
estimation on a Bently Nevada RK-4 rotor kit, doi:10.5281/zenodo.23152815; files
copied unchanged from the repository M-Nouioua/rk4-rotor-unbalance-estimation at
commit f3fd3be0, MIT licence; raw recordings CC BY 4.0). Each loader returns a
:class:`sklearn.utils.Bunch` whose ``DESCR`` is the full provenance note (units,
conventions, what is known to be in the data) and ``license`` the licence text.

The data stay in their native units, as recorded: the run-up in rpm and volts, the
unbalance campaign in mils and g mm. The loaders say so; convert with the factors
given there (1 V = 127 um = 5 mils at the proximitor output).

The Silverbox circuit (Wigren & Schoukens 2013) is the standard real benchmark of
nonlinear system identification: a NARX model that holds there holds on measured data.
"""

from __future__ import annotations

from importlib import resources

import pandas as pd
from sklearn.utils import Bunch

__all__ = ["load_rk4_runup", "load_rk4_unbalance", "load_silverbox", "data_path",
           "dataset_path", "DATASETS"]

#: the shipped datasets by the name the command line takes: (folder, data file, what it is)
DATASETS = {
    "rk4-runup": ("rk4_runup", "runup_bode.csv",
                  "RK-4 rotor kit run-up, order-tracked 1x per revolution (sknarx gap)"),
    "rk4-unbalance": ("rk4_unbalance", "features_1x.csv",
                      "RK-4 two-plane unbalance campaign, 1x vectors (sknarx unbalance)"),
    "silverbox": ("silverbox", "SNLS80mV.csv",
                  "Silverbox circuit, input and output voltages (NARX benchmark)"),
}

#: Silverbox sampling frequency (Hz): 10^7 / 2^14
SILVERBOX_FS = 1e7 / 2**14
#: Silverbox rows (start, stop) of the test arrow, the estimation multisines and the
#: range of the arrow whose amplitude stays within the estimation data
_SILVERBOX_TEST = (100, 40500)
_SILVERBOX_ESTIMATION = (40500, 127420)
_SILVERBOX_MULTISINE = (460, 8192, 40)  # transient, steady, trailing samples



def data_path(dataset: str, filename: str):
    """Path of a file shipped in ``sknarx/datasets/<dataset>/`` (for the command line)."""
    path = resources.files(__name__).joinpath(dataset, filename)
    if not path.is_file():
        raise FileNotFoundError(f"sknarx ships no {dataset}/{filename}.")
    return path


def dataset_path(name: str) -> str:
    """Path of the data file of the shipped dataset ``name`` (a key of :data:`DATASETS`),
    as ``sknarx datasets path NAME`` prints it.

    Examples
    --------
    >>> from sknarx.datasets import dataset_path
    >>> dataset_path("rk4-runup").endswith("runup_bode.csv")
    True
    """
    if name not in DATASETS:
        raise ValueError(f"no shipped dataset {name!r}; give one of {', '.join(DATASETS)}.")
    folder, filename, _ = DATASETS[name]
    return str(data_path(folder, filename))


def _text(dataset, filename):
    return data_path(dataset, filename).read_text(encoding="utf-8")


def load_rk4_runup() -> Bunch:
    """The real run-up of the RK-4 rotor kit: one order-tracked 1x vector per revolution.

    6,921 revolutions: a ramp at about 228 rpm/s from 1037 to about 4990 rpm, then a
    dwell near 5000 rpm. Slow-roll runout is *not* subtracted; the ramp is far from
    quasi-steady (see ``DESCR``).

    Returns
    -------
    Bunch
        ``frame``: DataFrame with columns ``rpm`` (rev/min), ``amp_1x`` (1x amplitude,
        0-to-peak, **volts** at the proximitor: x 127 for micrometres),
        ``phase_1x_deg`` (degrees, ``x = A cos(theta + phase)``, in (-180, 180]) and
        ``amp_1x_um`` (the source's column, most likely 5x too small: prefer
        ``amp_1x * 127``); ``filename`` (the CSV, for ``sknarx gap --measured``);
        ``rig`` (the authors' ``rig.yaml``, text); ``DESCR``; ``license``.

    Examples
    --------
    >>> from sknarx.datasets import load_rk4_runup
    >>> runup = load_rk4_runup()
    >>> runup.frame.shape
    (6921, 4)
    >>> round(float(runup.frame.rpm.min()))
    1037
    """
    path = data_path("rk4_runup", "runup_bode.csv")
    return Bunch(frame=pd.read_csv(path), filename=str(path),
                 rig=_text("rk4_runup", "rig.yaml"),
                 DESCR=_text("rk4_runup", "PROVENANCE.md"),
                 license=_text("rk4_runup", "LICENSE"))


def load_rk4_unbalance() -> Bunch:
    """The real two-plane unbalance campaign on the RK-4 rotor kit: 1x vectors per record.

    561 records of 95 conditions (85 labelled, 10 whose labels were sealed: ``labeled``
    is 0 and the ``U*`` columns are empty), three mounts per condition and speed, two
    sub-critical dwell speeds (N1 ~1005 rpm, N2 ~1206 rpm), four probes.

    Returns
    -------
    Bunch
        ``frame``: DataFrame, one row per record: identity columns (``condition_id``,
        ``block``, ``speed_id``, ``mount_idx``, ``acq_idx``, ``labeled``), ``rpm``
        (rev/min), the applied unbalance per disk ``U1_re, U1_im, U2_re, U2_im`` in
        **g mm** (angle ``atan2(im, re)`` in degrees on the disk's engraved scale),
        ``disk1_loaded``/``disk2_loaded`` (applied unbalance >= 6 g mm), and per probe
        ``plane{1,2}_{x,y}_1x_re/_im`` (runout-compensated 1x), ``_resp_re/_im`` (minus
        the balanced baseline) and ``_2x_amp``, all in **mils** 0-to-peak with the
        phase a positive *lag* after the keyphasor; ``filename``; ``DESCR``;
        ``license``.

    Examples
    --------
    >>> from sknarx.datasets import load_rk4_unbalance
    >>> campaign = load_rk4_unbalance()
    >>> campaign.frame.condition_id.nunique(), int((campaign.frame.labeled == 0).sum() > 0)
    (95, 1)
    """
    path = data_path("rk4_unbalance", "features_1x.csv")
    return Bunch(frame=pd.read_csv(path), filename=str(path),
                 DESCR=_text("rk4_unbalance", "PROVENANCE.md"),
                 license=_text("rk4_unbalance", "LICENSE"))


def load_silverbox() -> Bunch:
    """The Silverbox circuit: the standard real benchmark of nonlinear identification.

    An electronic Duffing-type oscillator (``m y'' + d y' + (a + b y^2) y = u``) driven
    by voltage ``V1`` with response ``V2``, sampled at 610.35 Hz (Wigren & Schoukens,
    ECC 2013; see ``DESCR``).

    Returns
    -------
    Bunch
        ``frame``: the whole file as a DataFrame with columns ``V1`` (input, V) and
        ``V2`` (output, V), 131,072 rows;
        ``estimation``: list of the 10 multisine realisations, each a DataFrame of
        8,692 rows (460 transient samples, which serve as lag history, then the 8,192
        steady ones and 40 trailing), columns ``V1``, ``V2``;
        ``test``: the test arrow, rows 100-40,499 of the file (40,400 rows);
        ``steady_start``: 460, the first steady sample of each realisation;
        ``within_range``: 30,000, the number of arrow samples whose amplitude stays
        within the estimation data (the quoted figures discard the first 100 of them);
        ``fs``: sampling frequency (Hz); ``filename``; ``DESCR``; ``license``.

    Examples
    --------
    >>> from sknarx.datasets import load_silverbox
    >>> sb = load_silverbox()
    >>> len(sb.estimation), sb.estimation[0].shape, sb.test.shape
    (10, (8692, 2), (40400, 2))
    >>> round(sb.fs, 2)
    610.35
    """
    path = data_path("silverbox", "SNLS80mV.csv")
    frame = pd.read_csv(path, usecols=["V1", "V2"])
    a, b = _SILVERBOX_ESTIMATION
    n = sum(_SILVERBOX_MULTISINE)
    estimation = [frame.iloc[i:i + n].reset_index(drop=True) for i in range(a, b, n)]
    test = frame.iloc[slice(*_SILVERBOX_TEST)].reset_index(drop=True)
    return Bunch(frame=frame, estimation=estimation, test=test,
                 steady_start=_SILVERBOX_MULTISINE[0], within_range=30000,
                 fs=SILVERBOX_FS, filename=str(path),
                 DESCR=_text("silverbox", "PROVENANCE.md"),
                 license=_text("silverbox", "LICENSE"))
