"""Object-centric field grids of the implicit planner (DESIGN "Implicit neural trajectory planner").

On an 0.80 m cube of 33³ nodes around the target, computed from a labelled point cloud:
D_t (inverse geodesic distance to the target, fast marching), D_o (inverse distance to the nearest
obstacle point) and, given a demonstration, the time of arrival φ and D_toa. :func:`descend` follows φ
to the goal; :func:`compute_many` builds many field sets for a dataset with a cache and a process pool.
"""

from hsi_planning.fields.cache import (
    FIELDS_VERSION,
    FieldJob,
    compute_many,
    fields_cache_key,
    load_fields,
    save_fields,
)
from hsi_planning.fields.config import FieldConfig
from hsi_planning.fields.descent import (
    Descent,
    DescentConfig,
    DescentField,
    descend,
    descend_field,
    prepare_descent,
)
from hsi_planning.fields.distance import inverse_field, point_distance, target_distance
from hsi_planning.fields.field_set import FieldSet, compute_fields
from hsi_planning.fields.grid import GridSpec
from hsi_planning.fields.occupancy import TargetObstaclePoints, check_target_accessible, split_cloud, voxelize
from hsi_planning.fields.toa import DemoPath, demo_path, speed_field, time_of_arrival

__all__ = [
    "FIELDS_VERSION",
    "DemoPath",
    "Descent",
    "DescentConfig",
    "DescentField",
    "FieldConfig",
    "FieldJob",
    "FieldSet",
    "GridSpec",
    "TargetObstaclePoints",
    "check_target_accessible",
    "compute_fields",
    "compute_many",
    "demo_path",
    "descend",
    "descend_field",
    "fields_cache_key",
    "inverse_field",
    "load_fields",
    "point_distance",
    "prepare_descent",
    "save_fields",
    "speed_field",
    "split_cloud",
    "target_distance",
    "time_of_arrival",
    "voxelize",
]
