"""Unbalance per disk from 1x response vectors, through a rotor model updated on labelled
conditions (``sknarx unbalance``)."""

from .campaign import Campaign, CampaignScoring, load_campaign
from .model import RigInfluenceModel, UnbalanceModel
from .report import write_unbalance_outputs
from .study import UnbalanceStudy, identify_unbalance

__all__ = ["Campaign", "CampaignScoring", "load_campaign", "RigInfluenceModel",
           "UnbalanceModel", "UnbalanceStudy", "identify_unbalance", "write_unbalance_outputs"]
