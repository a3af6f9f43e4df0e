"""The sensor simulator: power-law noise generators, the thermal model (room, plate, die),
presets and the simulated record files."""
