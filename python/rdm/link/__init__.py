"""Byte and frame transports, each chosen by one configuration string.

UARTs go through pyserial (device paths, ptys, ``loop://``); CAN goes through python-can
buses (``socketcan:vcan0``, ``socketcan:can0``, ``virtual:name``).
"""
