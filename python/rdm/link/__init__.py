"""Byte and frame transports: pyserial ports and ptys, python-can buses, chosen by one configuration string."""
