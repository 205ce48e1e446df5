"""Robot models, retargeting (IK), timing, the MuJoCo execution check and robot backends."""

__version__ = "0.1.0"
