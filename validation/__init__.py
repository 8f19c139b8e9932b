"""Blind validation of the gap diagnosis (not installed with the package).

``plants/``: rotor families that share no simulation or effect code with
``sknarx.rotor``; ``trials``: which trials are drawn and how one is logged; ``run``:
the runner (joblib, or a dask.distributed cluster); ``score``: the rates, decided by
the package's verdict rule on the logged trials; ``fit``: the rule's tuned values on
pilot trials. ``docs/validation.md`` describes the protocol and the current scores.
"""
