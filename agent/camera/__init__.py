"""Camera stage of the flight software (issue 4): pinhole model, spacecraft silhouette, ROI renderer."""
from swarmhil.agent.camera.model import R_CAM_FROM_LVLH, R_LVLH_FROM_CAM, Camera, quat_to_matrix
from swarmhil.agent.camera.render import Detector, Renderer, RoiStack, compose_frame, silhouette_area_px
from swarmhil.agent.camera.shape import SpacecraftShape

__all__ = [
    "Camera",
    "Detector",
    "R_CAM_FROM_LVLH",
    "R_LVLH_FROM_CAM",
    "Renderer",
    "RoiStack",
    "SpacecraftShape",
    "compose_frame",
    "quat_to_matrix",
    "silhouette_area_px",
]
