"""Python side of the IpmsmPlant: the default motor (see plant/motor/)."""
