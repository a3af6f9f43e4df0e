"""Hardware and its stand-ins, chosen in one place (``rig.py``).

- ``adxl355.py``, ``registers.py`` the driver and the register map as data;
- ``transport.py``  the SPI and I2C transports (spidev, smbus2);
- ``emulator.py``   the register-level ADXL355 emulator; ``simulation.py`` feeds it;
- ``ds18b20.py``, ``w1_sysfs.py`` the DS18B20 bank over the kernel's w1 sysfs tree;
- ``interrupt.py``  INT1/INT2 through the GPIO character device (libgpiod);
- ``source.py``     the typed SampleSource contract between driver and reader;
- ``thread_priority.py`` real-time priority for the reader where the unit allows it.
"""
