"""The end-to-end pick-and-place demo (``hsi demo``): scripted clicks (:mod:`.tasks`), one task through
scheduler, planner, retargeting and the MuJoCo check (:mod:`.pipeline`), plots, video and reports.
"""
