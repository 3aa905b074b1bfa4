"""The default EV traction IPMSM: saturation model, iron-loss model, map generator, target check.

- saturation.py       energy-consistent (reciprocal) flux-linkage model psi(i_d, i_q)
- iron_loss.py        iron loss P_fe = k_h f b^alpha + k_e f^2 b^2, b = |psi| / psi_ref
- make_default_map.py writes fmu_src/resources/ev_ipmsm_default.csv
                      (python -m tools.default_motor.make_default_map)
- check_targets.py    brute-force torque-speed envelope, efficiency map, targets
                      (python -m tools.default_motor.check_targets)
"""
