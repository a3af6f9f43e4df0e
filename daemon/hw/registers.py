"""The ADXL355 register map, declared as data (datasheet Rev. 0+, Table "Register Map").

Both the driver (:mod:`avard.daemon.hw.adxl355`) and the emulator (:mod:`avard.daemon.hw.emulator`)
read this one table, so a wrong address or reset value cannot be right in one and wrong in the
other without a test noticing. Nothing here touches hardware.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from avard.core.errors import ConfigError


@dataclass(frozen=True)
class Field:
    """A bit field inside a register: ``(value >> shift) & mask``."""

    shift: int
    width: int

    @property
    def mask(self) -> int:
        return (1 << self.width) - 1

    def get(self, value: int) -> int:
        return (value >> self.shift) & self.mask

    def put(self, value: int, field_value: int) -> int:
        """``value`` with this field replaced by ``field_value`` (other bits kept)."""
        if not 0 <= field_value <= self.mask:
            raise ValueError(f"{field_value} does not fit in a {self.width}-bit field")
        return (value & ~(self.mask << self.shift)) | (field_value << self.shift)


@dataclass(frozen=True)
class Register:
    """One register: address, power-on value, access and bit fields.

    ``config`` marks registers the datasheet says to program only in standby; the emulator
    ignores writes to them in measurement mode, as the part does.
    """

    name: str
    address: int
    reset: int = 0x00
    access: str = "rw"  # "r", "rw" or "w"
    config: bool = False
    fields: dict[str, Field] = field(default_factory=dict)


_REGS: tuple[Register, ...] = (
    Register("DEVID_AD", 0x00, 0xAD, "r"),
    Register("DEVID_MST", 0x01, 0x1D, "r"),
    Register("PARTID", 0x02, 0xED, "r"),
    Register("REVID", 0x03, 0x01, "r"),
    Register("STATUS", 0x04, 0x00, "r", fields={
        "DATA_RDY": Field(0, 1), "FIFO_FULL": Field(1, 1), "FIFO_OVR": Field(2, 1),
        "ACTIVITY": Field(3, 1), "NVM_BUSY": Field(4, 1)}),
    Register("FIFO_ENTRIES", 0x05, 0x00, "r", fields={"ENTRIES": Field(0, 7)}),
    Register("TEMP2", 0x06, 0x00, "r", fields={"TEMP_HI": Field(0, 4)}),
    Register("TEMP1", 0x07, 0x00, "r"),
    Register("XDATA3", 0x08, 0x00, "r"),
    Register("XDATA2", 0x09, 0x00, "r"),
    Register("XDATA1", 0x0A, 0x00, "r"),
    Register("YDATA3", 0x0B, 0x00, "r"),
    Register("YDATA2", 0x0C, 0x00, "r"),
    Register("YDATA1", 0x0D, 0x00, "r"),
    Register("ZDATA3", 0x0E, 0x00, "r"),
    Register("ZDATA2", 0x0F, 0x00, "r"),
    Register("ZDATA1", 0x10, 0x00, "r"),
    Register("FIFO_DATA", 0x11, 0x00, "r"),
    Register("OFFSET_X_H", 0x1E, 0x00, config=True),
    Register("OFFSET_X_L", 0x1F, 0x00, config=True),
    Register("OFFSET_Y_H", 0x20, 0x00, config=True),
    Register("OFFSET_Y_L", 0x21, 0x00, config=True),
    Register("OFFSET_Z_H", 0x22, 0x00, config=True),
    Register("OFFSET_Z_L", 0x23, 0x00, config=True),
    Register("ACT_EN", 0x24, 0x00, config=True),
    Register("ACT_THRESH_H", 0x25, 0x00, config=True),
    Register("ACT_THRESH_L", 0x26, 0x00, config=True),
    Register("ACT_COUNT", 0x27, 0x01, config=True),
    Register("FILTER", 0x28, 0x00, config=True, fields={
        "ODR_LPF": Field(0, 4), "HPF_CORNER": Field(4, 3)}),
    Register("FIFO_SAMPLES", 0x29, 0x60, config=True, fields={"SAMPLES": Field(0, 7)}),
    Register("INT_MAP", 0x2A, 0x00, config=True),
    Register("SYNC", 0x2B, 0x00, config=True, fields={
        "EXT_SYNC": Field(0, 2), "EXT_CLK": Field(2, 1)}),
    Register("RANGE", 0x2C, 0x81, config=True, fields={
        "RANGE": Field(0, 2), "INT_POL": Field(6, 1), "I2C_HS": Field(7, 1)}),
    Register("POWER_CTL", 0x2D, 0x01, fields={
        "STANDBY": Field(0, 1), "TEMP_OFF": Field(1, 1), "DRDY_OFF": Field(2, 1)}),
    Register("SELF_TEST", 0x2E, 0x00, fields={"ST1": Field(0, 1), "ST2": Field(1, 1)}),
    Register("RESET", 0x2F, 0x00, "w"),
)

#: name → Register
REGISTERS: dict[str, Register] = {r.name: r for r in _REGS}
#: address → Register
BY_ADDRESS: dict[int, Register] = {r.address: r for r in _REGS}
#: name → address, for terse use in the driver
ADDR: dict[str, int] = {r.name: r.address for r in _REGS}
#: Highest register address plus one (the register file size).
N_REGISTERS = 0x30

# Identification values and their meaning when they are wrong.
DEVID_AD = 0xAD
DEVID_MST = 0x1D
PARTID_ADXL355 = 0xED
PARTID_ADXL359 = 0xE9
RESET_CODE = 0x52  # written to RESET: power-on reset

# Status bits.
#: INT_MAP bits: FIFO_FULL (watermark) on INT1 / INT2, DATA_RDY on INT1 / INT2
INT_MAP_RDY_EN1 = 0x01
INT_MAP_FULL_EN1 = 0x02
INT_MAP_RDY_EN2 = 0x10
INT_MAP_FULL_EN2 = 0x20
STATUS_DATA_RDY = 0x01
STATUS_FIFO_FULL = 0x02
STATUS_FIFO_OVR = 0x04
STATUS_ACTIVITY = 0x08
STATUS_NVM_BUSY = 0x10

# POWER_CTL bits.
POWER_STANDBY = 0x01
POWER_TEMP_OFF = 0x02
POWER_DRDY_OFF = 0x04

# SELF_TEST bits.
SELF_TEST_ST1 = 0x01
SELF_TEST_ST2 = 0x02

# FIFO geometry: 96 one-axis locations (32 XYZ sets) plus a 3-location sync buffer.
FIFO_LOCATIONS = 96
FIFO_SYNC_LOCATIONS = 3
FIFO_OVERRUN_LOCATIONS = FIFO_LOCATIONS + FIFO_SYNC_LOCATIONS  # 99: a write past it overruns
ENTRY_BYTES = 3
SET_BYTES = 3 * ENTRY_BYTES
FIFO_MARK_X = 0x01  # third byte, bit 0: this entry is an X-axis entry
FIFO_MARK_EMPTY = 0x02  # third byte, bit 1: the FIFO was empty, data invalid

# Data format: 20-bit two's complement, left-justified in 3 bytes.
DATA_BITS = 20
DATA_MIN = -(1 << 19)
DATA_MAX = (1 << 19) - 1
OFFSET_LSB_COUNTS = 16  # one OFFSET register LSB equals 16 data LSB (OFFSET ↔ XDATA[19:4])

#: range (±g) → (RANGE code, typical sensitivity in LSB/g)
RANGES: dict[int, tuple[int, float]] = {2: (0b01, 256000.0), 4: (0b10, 128000.0),
                                        8: (0b11, 64000.0)}
RANGE_BY_CODE: dict[int, int] = {code: g for g, (code, _) in RANGES.items()}

#: standard gravity used to turn counts into m/s² (CGPM 1901), m/s²
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class Rate:
    """One FILTER.ODR_LPF setting: output data rate, low-pass corner and filter group delay."""

    code: int
    odr_hz: float
    lowpass_hz: float
    group_delay_samples: float


#: FILTER.ODR_LPF code → Rate (datasheet table "Output data rate and filter"; group delays
#: from the datasheet's filter description, in output samples).
RATES: tuple[Rate, ...] = (
    Rate(0x0, 4000.0, 1000.0, 2.52),
    Rate(0x1, 2000.0, 500.0, 2.00),
    Rate(0x2, 1000.0, 250.0, 1.78),
    Rate(0x3, 500.0, 125.0, 1.63),
    Rate(0x4, 250.0, 62.5, 1.57),
    Rate(0x5, 125.0, 31.25, 1.54),
    Rate(0x6, 62.5, 15.625, 1.51),
    Rate(0x7, 31.25, 7.8125, 1.49),
    Rate(0x8, 15.625, 3.90625, 1.50),
    Rate(0x9, 7.8125, 1.953125, 1.50),
    Rate(0xA, 3.90625, 0.9765625, 1.50),
)
RATE_BY_CODE: dict[int, Rate] = {r.code: r for r in RATES}

# Temperature channel: T = 25 °C + (raw − intercept) / slope (datasheet, "Temperature sensor").
TEMP_SLOPE_LSB_PER_C = -9.05
TEMP_INTERCEPT_REV0 = 1852.0  # LSB at 25 °C, Rev. 0 datasheet
TEMP_INTERCEPT_LATER = 1885.0  # LSB at 25 °C, later revisions and the Linux driver

#: Typical self-test responses (ST1+ST2 minus ST1 only), g, per axis X, Y, Z (datasheet).
SELF_TEST_TYPICAL_G = (0.3, 0.3, 1.5)
#: Accepted windows for the self-test delta, g. The typical values ±~2× are a conservative
#: pass band: a dead axis shows ~0 and a disconnected one shows nonsense; re-check against the
#: datasheet's min/max for a production screen.
SELF_TEST_LIMITS_G = ((0.1, 0.6), (0.1, 0.6), (0.5, 3.0))


def rate_for(odr_hz: float) -> Rate:
    """The ODR setting for ``odr_hz``, or a ``ConfigError`` naming the nearest valid rates.

    Matching allows 0.1 % so that the rounded values of the datasheet (7.813 Hz) are accepted.
    """
    for r in RATES:
        if abs(odr_hz - r.odr_hz) <= 1e-3 * r.odr_hz:
            return r
    above = [r.odr_hz for r in RATES if r.odr_hz > odr_hz]
    below = [r.odr_hz for r in RATES if r.odr_hz < odr_hz]
    near = ([f"{min(above):g} Hz"] if above else []) + ([f"{max(below):g} Hz"] if below else [])
    valid = ", ".join(f"{r.odr_hz:g}" for r in RATES)
    raise ConfigError(
        f"the ADXL355 has no {odr_hz:g} Hz output data rate; nearest: {' and '.join(near)} "
        f"(valid rates: {valid} Hz). Choose one of them in the config (odr_hz)."
    )


def range_code(range_g: int) -> int:
    """RANGE register code for ±``range_g`` g, or a ``ConfigError``."""
    try:
        return RANGES[int(range_g)][0]
    except (KeyError, ValueError, TypeError):
        raise ConfigError(
            f"the ADXL355 has no ±{range_g} g range; choose 2, 4 or 8 (range_g)"
        ) from None


def sensitivity_lsb_per_g(range_g: int) -> float:
    """Typical sensitivity, LSB/g, for ±``range_g`` g (±8 % part to part)."""
    range_code(range_g)
    return RANGES[int(range_g)][1]


def counts_to_mps2(range_g: int) -> float:
    """Scale factor from raw counts to m/s² with the typical sensitivity."""
    return STANDARD_GRAVITY / sensitivity_lsb_per_g(range_g)


def temperature_from_raw(raw: int | float, intercept_lsb: float = TEMP_INTERCEPT_LATER) -> float:
    """Chip temperature in °C from the 12-bit TEMP value: 25 + (raw − intercept) / (−9.05)."""
    return 25.0 + (float(raw) - intercept_lsb) / TEMP_SLOPE_LSB_PER_C


def raw_from_temperature(temp_c: float, intercept_lsb: float = TEMP_INTERCEPT_LATER) -> int:
    """Inverse of :func:`temperature_from_raw`, rounded and clipped to 12 bits."""
    raw = round(intercept_lsb + (temp_c - 25.0) * TEMP_SLOPE_LSB_PER_C)
    return min(max(raw, 0), 0xFFF)
