"""Order-tracked (Bode) records diagnosed against a linear beam rotor: the gap diagnosis's
second front end (``sknarx gap --rotor FILE`` with ``[rotor] model = "beam"``).

:mod:`records` loads and bins a 1x record, :mod:`model` is the rotor's order response at
a probe (steady or a simulated run-up), :mod:`diagnosis` fits the candidates through the
gap core (:mod:`sknarx.gap.search`, :class:`~sknarx.gap.VerdictRule`), :mod:`report`
writes ``diagnosis.json``, ``bode_fit.csv``, figures and ``report.html``.
"""

from .diagnosis import CANDIDATES, diagnose_order_domain
from .records import bin_bode, load_bode, runup_rate
from .report import write_bode_outputs

__all__ = ["diagnose_order_domain", "CANDIDATES", "load_bode", "bin_bode", "runup_rate",
           "write_bode_outputs"]
