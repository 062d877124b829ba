"""Type stubs of the native module ``scarp._scarp`` (the engine behind the ``scarp`` package;
call the package's functions instead). Configurations are JSON strings of the Rust serde
structs; reports come back as JSON strings."""

from typing import Optional, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

MeshArrays = Tuple[
    npt.NDArray[np.float32],
    npt.NDArray[np.uint32],
    Optional[npt.NDArray[np.uint8]],
    Optional[npt.NDArray[np.float32]],
]

class TsdfVolume:
    def __init__(self, config_json: str, roi: Optional[str] = None) -> None: ...
    def integrate(
        self,
        depth_m: npt.NDArray[np.float32],
        color: npt.NDArray[np.uint8],
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        world_from_camera: npt.NDArray[np.float64],
    ) -> str: ...
    def extract_mesh(
        self, min_weight: float = 0.0, min_component_triangles: int = 0, min_observations: int = 0
    ) -> MeshArrays: ...
    def stats(self) -> str: ...
    def config_json(self) -> str: ...
    def clear(self) -> None: ...

class RgbdOdometry:
    def __init__(
        self, config_json: str, world_from_first_camera: Optional[npt.NDArray[np.float64]] = None
    ) -> None: ...
    def track(
        self,
        depth_m: npt.NDArray[np.float32],
        color: npt.NDArray[np.uint8],
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        prior: Optional[npt.NDArray[np.float64]] = None,
    ) -> Tuple[npt.NDArray[np.float64], str, str]: ...
    def reset(self) -> None: ...

class Sequence:
    def __init__(self, dir: str) -> None: ...
    def __len__(self) -> int: ...
    def camera(self) -> Tuple[float, float, float, float, int, int]: ...
    def frame(
        self, index: int
    ) -> Tuple[
        float,
        npt.NDArray[np.float32],
        npt.NDArray[np.uint8],
        Optional[npt.NDArray[np.float64]],
        Optional[npt.NDArray[np.float64]],
    ]: ...

def bundle_adjust_bal(path: str, config_json: str, threads: Optional[int] = None) -> str: ...
def fragility(
    vertices: npt.NDArray[np.float32],
    triangles: npt.NDArray[np.uint32],
    config_json: str,
    contact_height_m: Optional[float] = None,
    scan: bool = False,
) -> str: ...
def eval_mesh(
    vertices: npt.NDArray[np.float32],
    triangles: npt.NDArray[np.uint32],
    gt_vertices: npt.NDArray[np.float32],
    gt_triangles: npt.NDArray[np.uint32],
    config_json: str,
) -> str: ...
def eval_traj(gt: npt.NDArray[np.float64], est: npt.NDArray[np.float64], config_json: str) -> str: ...
def read_tum(path: str) -> npt.NDArray[np.float64]: ...
def read_ply(path: str) -> MeshArrays: ...
def write_ply(
    path: str,
    vertices: npt.NDArray[np.float32],
    triangles: npt.NDArray[np.uint32],
    colors: Optional[npt.NDArray[np.uint8]] = None,
    ascii: bool = False,
) -> None: ...
def write_glb_file(
    path: str,
    vertices: npt.NDArray[np.float32],
    triangles: npt.NDArray[np.uint32],
    colors: Optional[npt.NDArray[np.uint8]] = None,
    name: str = "mesh",
) -> None: ...
