"""A machine's parameters from its flux map's `# key: value` metadata (the map's own data sheet,
docs/spec/INTERFACE.md), with every value the map does not give named as an assumption. One
rule for `map show`, `map check` and the drive descriptions:

- a key the map lacks takes the default motor's value (fmu_src/resources/ev_ipmsm_default.csv,
  the FMUs' defaults), and is listed;
- except the iron loss's flux reference fe_psi_ref when the map gives no iron loss: the default
  motor's coefficients are kept, and fe_psi_ref is scaled so that b = |psi| / fe_psi_ref is the
  same at this map's largest flux inside its current limit as at the default motor's (an
  8-pole 14 kg core's losses on another machine: a named guess, never a crash on psi_m = 0);
- and the current limit, which is the map's own reach (the largest current its grid covers
  in every direction): the default motor's 500 A says nothing of another machine's grid;
  and the top speed, which is then unknown (None).
"""
from __future__ import annotations

import numpy as np

from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, read_flux_map
from scenarios.maps.metadata import metadata_keys

#: parameter name (the FMUs' and the drive descriptions') -> the metadata key that gives it: the
#: one table (scenarios.maps.metadata), but for the rotor's inertia J, which is the vehicle side's
METADATA_KEYS = {k.parameter: k.key for k in metadata_keys().values() if k.parameter != "J"}
#: the iron-loss model's coefficients hold together (one core, one flux reference): all or none
IRON_LOSS = ("fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref")

_DEFAULT: FluxMap | None = None


def default_map() -> FluxMap:
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = read_flux_map(DEFAULT_MAP)
    return _DEFAULT


def grid_reach(fmap: FluxMap) -> float:
    """The largest current the grid covers in every direction of the motoring and generating half
    plane i_d <= 0, A."""
    return float(min(-fmap.i_d[0], -fmap.i_q[0], fmap.i_q[-1]))


def grid_resolution(fmap: FluxMap) -> float:
    """The smallest current limit the grid resolves, A: the distance from zero current to its
    nearest grid node in each of the directions -i_d, +i_q and -i_q, the largest of the three. A
    smaller I_max circle holds no grid cell of the operating region (no node but perhaps the
    origin): no inductance, reciprocity or flux figure inside it comes from the map's data."""
    def nearest(axis, sign):
        away = sign * axis[sign * axis > 0]
        return float(away.min()) if away.size else float("inf")
    return max(nearest(fmap.i_d, -1), nearest(fmap.i_q, 1), nearest(fmap.i_q, -1))


def largest_flux(fmap: FluxMap, I_max: float) -> float:
    """The largest flux-linkage magnitude at the grid nodes inside |i| <= I_max, Wb."""
    I_d, I_q = np.meshgrid(fmap.i_d, fmap.i_q, indexing="ij")
    inside = np.hypot(I_d, I_q) <= I_max * (1 + 1e-9)
    return float(np.hypot(fmap.psi_d, fmap.psi_q)[inside].max())


def machine_values(fmap: FluxMap, given: dict | None = None) -> tuple[dict, list[str]]:
    """parameter -> value (SI; pole_pairs an int: a count the map states is whole, by the rule of
    scenarios.maps.metadata) and the list of assumptions, in words. `given`
    (parameter -> value, e.g. a drive description's or the command line's) overrides the map."""
    given = given or {}
    dmap = default_map()
    values, assumed = {}, []
    iron_given = [k for k in IRON_LOSS if k in given or METADATA_KEYS[k] in fmap.metadata]
    for name, key in METADATA_KEYS.items():
        if name in given and given[name] is not None:
            values[name] = given[name]
        elif key in fmap.metadata:
            values[name] = fmap.number(key)
        elif name == "I_max":
            values[name] = grid_reach(fmap)
            assumed.append(f"I_max = {values[name]:g} A: the map's reach (no `I_max_A` in its metadata)")
        elif name == "w_m_max":  # the machine's own, or none (the default motor's says nothing of it)
            values[name] = None
            assumed.append("w_m_max: none (no `w_m_max_rad_s` in the map's metadata): the controller FMU's default "
                           "for its tables' speed axis, no top-speed flag")
        else:
            values[name] = dmap.number(key)
            if name not in IRON_LOSS or not iron_given:
                assumed.append(f"{name} = {values[name]:g}: the default motor's (no `{key}` in the map's metadata)")
    if not iron_given:
        values["fe_psi_ref"] = dmap.number("fe_psi_ref_Wb") * largest_flux(fmap, values["I_max"]) / \
            largest_flux(dmap, dmap.number("I_max_A"))
        assumed = [a for a in assumed if not a.startswith("fe_psi_ref")]
        assumed.append(f"fe_psi_ref = {values['fe_psi_ref']:.4g} Wb: the default motor's, scaled by this map's largest "
                       "flux linkage within its current limit over the default motor's (no iron-loss metadata)")
    if iron_given and len(iron_given) < len(IRON_LOSS):
        missing = [k for k in IRON_LOSS if k not in iron_given]
        assumed.append(f"iron loss: {', '.join(missing)} the default motor's, the rest the map's")
    return values, assumed
