"""Type stubs for the private compiled module ``insnav._core``."""
from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str

def mechanize(
    t: npt.ArrayLike,
    dtheta_b: npt.ArrayLike,
    dv_b: npt.ArrayLike,
    t0: float,
    pos_llh: npt.ArrayLike,
    v_n: npt.ArrayLike,
    rpy: npt.ArrayLike,
    coning: bool = True,
    sculling: bool = True,
) -> dict[str, np.ndarray]: ...

class earth:
    @staticmethod
    def gravity(lat: npt.ArrayLike, h: npt.ArrayLike) -> Any: ...
    @staticmethod
    def radius_meridian(lat: npt.ArrayLike) -> Any: ...
    @staticmethod
    def radius_prime_vertical(lat: npt.ArrayLike) -> Any: ...
    @staticmethod
    def geodetic_to_ecef(lat: float, lon: float, h: float) -> np.ndarray: ...
    @staticmethod
    def ecef_to_geodetic(r_e: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def C_en(lat: float, lon: float) -> np.ndarray: ...
    @staticmethod
    def omega_ie_n(lat: float) -> np.ndarray: ...
    @staticmethod
    def omega_en_n(lat: float, h: float, v_n: npt.ArrayLike) -> np.ndarray: ...

class rotation:
    @staticmethod
    def dcm_from_euler(rpy: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def euler_from_dcm(C_nb: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def quat_from_euler(rpy: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def quat_from_rotvec(phi: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def rotvec_from_quat(wxyz: npt.ArrayLike) -> np.ndarray: ...
    @staticmethod
    def dcm_from_rotvec(phi: npt.ArrayLike) -> np.ndarray: ...
