"""A fake /sys/bus/w1/devices tree for tests (reuse it: ``from tests.daemon.fake_w1 import
fake_w1_tree``).

    tree = fake_w1_tree(tmp_path, plate=24.5, ambient=21.0)
    bank = Ds18b20Bank({"plate": tree.ids["plate"], "ambient": tree.ids["ambient"]},
                       base_directory=tree.base)
    tree.set_temperature(tree.ids["plate"], 25.0)   # or set_crc_failure, set_reset_value,
                                                    # set_all_zero, remove, restore

The files carry real scratchpad bytes and CRC-8 (see avard.daemon.hw.w1_sysfs), so w1thermsensor
itself parses them exactly as on a Raspberry Pi.
"""

from __future__ import annotations

from pathlib import Path

from avard.daemon.hw.w1_sysfs import SysfsTree

#: Fixed, valid 1-Wire serials for named test sensors.
SERIALS = ("0316a2797cff", "0417b3808d00", "05a1c4919e11", "06b2d5a2af22")


class FakeW1Tree(SysfsTree):
    """A :class:`SysfsTree` that remembers which name got which id (``ids[name]``)."""

    def __init__(self, root: str | Path) -> None:
        super().__init__(root)
        self.ids: dict[str, str] = {}


def fake_w1_tree(tmp_path: Path, **sensors: float) -> FakeW1Tree:
    """A tree under ``tmp_path/w1/devices`` with one DS18B20 per keyword (name=°C)."""
    tree = FakeW1Tree(Path(tmp_path) / "w1" / "devices")
    for (name, temp), serial in zip(sensors.items(), SERIALS, strict=False):
        tree.ids[name] = tree.add(serial, temp)
    return tree
