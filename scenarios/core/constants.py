"""Numbers the scenarios share, each named once with where it comes from. SI units."""
from __future__ import annotations

#: K at 0 degC: the Celsius scale's offset (BIPM, The International System of Units, 9th ed.
#: 2019, section 2.3.1: t/degC = T/K - 273.15)
ZERO_CELSIUS_K = 273.15

#: K, 20 degC: the reference temperature of conductor resistance (IEC 60228:2004, resistances
#: at 20 degC; the copper coefficient alpha_cu = 0.00393 1/K is referred to it) and of magnet
#: grade data (remanence and its temperature coefficient quoted at 20 degC). The default motor's
#: R_s and flux map hold at it (T_winding_ref_K, T_magnet_ref_K in its map's metadata).
T_REFERENCE_K = ZERO_CELSIUS_K + 20.0

#: V, the DC link the default motor is designed for and the 2-D tables are built at: 96 NMC cells
#: in series at 3.7 V nominal (the 2018+ Nissan Leaf 40 kWh pack's 96s2p, 350 V nominal class);
#: the flux map's `u_dc_V` metadata (tools/default_motor/make_default_map.py writes it from here)
U_DC_NOMINAL_V = 355.0

#: the DC-link voltage a run may give the drive, relative to the battery's (Conditions.u_dc_scale):
#: at most twice, what a boost stage between battery and inverter commonly provides; below 1 models
#: a sagging or derated link. The CLI's --u-dc-scale and a study's u_dc_scale obey it.
U_DC_SCALE_MAX = 2.0
