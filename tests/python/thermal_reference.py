"""An independent implementation of the machine's thermal network for the tests, written from the
source (Wallscheid's low-order LPTN as implemented in github.com/wkirgsn/thermal-nn
aux/lptn_model.py and github.com/wkirgsn/diss-wk src/mawkutils/topology.py, docs/thermal.md), not
from the C++: test_thermal_network.py holds the C++ network against it, test_thermal_runs.py whole
runs through IpmsmDrive."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RPM = 2.0 * np.pi / 60.0  # rad/s per r/min
ZERO_C = 273.15
YOKE, TOOTH, WINDING, MAGNET = range(4)


@dataclass(frozen=True)
class Network:
    """Wallscheid's LPTN (values: the source's coefficient names in the comments)."""
    C_stator_yoke: float = 6.5093e3   # caps1
    C_stator_tooth: float = 0.437127e3  # caps2
    C_winding: float = 3.5105e3       # caps3
    C_magnet: float = 1.0666e4        # caps0
    R_yoke_winding: float = 0.0375    # const_Rs_sy_sw
    R_yoke_tooth: float = 0.0707      # const_Rs_sy_st
    R_tooth_winding: float = 0.0899   # const_Rs_sw_st
    R_coolant_yoke: float = 18e-3     # lin_Rs_bias
    k_coolant_yoke: float = -54e-4    # lin_Rs_slope

    def args(self) -> list[str]:
        base = Network()
        return [f"{k}={v!r}" for k, v in self.__dict__.items() if v != getattr(base, k)]

    def C(self) -> np.ndarray:
        return np.array([self.C_stator_yoke, self.C_stator_tooth, self.C_winding, self.C_magnet])

    def matrices(self, w_m: float, T_c: float) -> tuple[np.ndarray, np.ndarray]:
        """K (W/K, 4x4) and G_b (W/K, 4x2: coolant, ambient) with C dT/dt = P + G_b T_b - K T."""
        n = min(abs(w_m) / (6000.0 * RPM), 1.0)
        c = min(max((T_c - ZERO_C) / 100.0, 0.0), 1.0)
        r_exp = lambda a, b, s: a * np.exp(-n / b) + s  # noqa: E731
        R = {(YOKE, WINDING): self.R_yoke_winding, (YOKE, TOOTH): self.R_yoke_tooth,
             (TOOTH, WINDING): self.R_tooth_winding,
             (TOOTH, MAGNET): r_exp(1.7275, 0.1573, 0.3039), (WINDING, MAGNET): r_exp(0.8486, 0.1428, 0.2319)}
        K = np.zeros((4, 4))
        for (i, j), r in R.items():
            K[i, j] = K[j, i] = -1.0 / r
        Gb = np.zeros((4, 2))
        Gb[YOKE, 0] = 1.0 / (self.R_coolant_yoke * (1.0 + self.k_coolant_yoke * (100.0 * c - 20.0)))
        Gb[MAGNET, 0] = 1.0 / (0.3528 - 0.2484 * n + 0.0276 * c + 0.3331 * n * c)
        Gb[MAGNET, 1] = 1.0 / r_exp(0.6349, 0.1184, 0.1205)
        K[np.diag_indices(4)] = -K.sum(axis=1) + Gb.sum(axis=1)
        return K, Gb

    @staticmethod
    def losses(P_cu: float, P_fe: float, w_m: float, I_rms: float) -> np.ndarray:
        n = min(abs(w_m) / (6000.0 * RPM), 1.0)
        i = min(abs(I_rms) / 256.0, 1.0)
        k1 = min(max(0.5441 + 78e-4 * n + 0.0352 * i - 0.7438 * n * i, 0.0), 1.0)
        return np.array([0.8655 * k1 * P_fe, (1 - 0.8655) * k1 * P_fe, P_cu, (1 - k1) * P_fe])
