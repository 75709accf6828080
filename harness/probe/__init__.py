"""Stage 3, the probe: the field rig's protocol and the driver that applies it to every backend."""
