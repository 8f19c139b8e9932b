"""Plants independent of ``sknarx.rotor``, for blind validation of the gap diagnosis."""
