"""softenv: a Gymnasium environment and learning benchmark for soft-tissue deformation under a
force-input device.

The offline core (this package's top level) needs only numpy: the analytic tissue model, the
paper's data sets and the PCA shape model. Importing it registers the SoftSphere environments with
Gymnasium (``gym.make("SoftSphere-v0")``).
"""

from .envs import default_config, describe_config, make_config, register_envs
from .datasets import ForceShapeData, paper_dataset, split_by_contact, split_rows, workspace_dataset
from .forces import DorsumLayout, PaperLayout, Workspace, sample_workspace
from .geometry import SphereMesh, icosphere_mesh, latlong_mesh, make_mesh, paper_mesh
from .shape_model import ShapeModel
from .tissue import AnalyticTissue, TissueParams

__version__ = "0.1.0"

register_envs()

__all__ = [
    "AnalyticTissue", "DorsumLayout", "ForceShapeData", "PaperLayout", "ShapeModel", "SphereMesh", "TissueParams",
    "Workspace", "icosphere_mesh", "latlong_mesh", "make_mesh", "paper_dataset", "paper_mesh", "sample_workspace",
    "split_by_contact", "split_rows", "workspace_dataset", "default_config", "describe_config", "make_config",
    "register_envs",
]
