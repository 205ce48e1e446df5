"""Pure algorithms of the HSI stack: scenes, point clouds, fields, demonstrations, planners.

Nothing here imports the transport (``hsi_nodes``) or a hardware SDK.
"""

from hsi_planning.errors import HsiError

__all__ = ["HsiError"]
__version__ = "0.1.0"
