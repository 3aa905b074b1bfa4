"""ipmsm-fmu scenarios: co-simulation of the IpmsmController and IpmsmPlant FMUs with fmpy."""
