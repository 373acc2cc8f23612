"""Reserved topic ids, endpoint types, buffer limits and timing of rosserial as Spinal uses it
(fact sheet sec. 1.2, 1.3, 1.5)."""

from __future__ import annotations

from enum import IntEnum

SYNC = 0xFF
PROTOCOL_VERSION = 0xFE  # rosserial v2 ("hydro+"); 0xFF was v1
FRAME_OVERHEAD = 8  # FF FE len_lo len_hi len_chk topic_lo topic_hi ... chk


class TopicId(IntEnum):
    """Reserved ids of ``rosserial_msgs/TopicInfo`` (ID_* constants)."""

    PUBLISHER = 0
    SUBSCRIBER = 1
    SERVICE_SERVER = 2
    SERVICE_CLIENT = 4
    PARAMETER_REQUEST = 6
    LOG = 7
    TIME = 10
    TX_STOP = 11


class Endpoint(IntEnum):
    """The topic id a TopicInfo record travels on = the kind of endpoint it announces."""

    PUBLISHER = 0  # device -> PC topic
    SUBSCRIBER = 1  # PC -> device topic
    SERVICE_RESPONSE = 2  # ID_SERVICE_SERVER + ID_PUBLISHER: device answers
    SERVICE_REQUEST = 3  # ID_SERVICE_SERVER + ID_SUBSCRIBER: device receives requests


class LogLevel(IntEnum):
    """``rosserial_msgs/Log`` levels."""

    DEBUG = 0
    INFO = 1
    WARN = 2
    ERROR = 3
    FATAL = 4


FIRST_USER_TOPIC_ID = 100  # ids below are reserved; >= 100 only flow once configured
# Spinal's NodeHandleStm_<50, 50, 512, 1024> (sec. 1.5)
MAX_SUBSCRIBERS = 50
MAX_PUBLISHERS = 50
INPUT_SIZE = 512  # largest payload the client accepts
OUTPUT_SIZE = 1024  # largest frame (payload + 8) the client sends
SERVER_BUFFER_MAX = 1023  # rosserial_server receive buffer: payload + checksum must fit

# Client timing, in ms of the MCU tick (HAL_GetTick)
SERIAL_MSG_TIMEOUT_MS = 20  # a frame must complete within 20 ms of its first 0xFF
SYNC_SECONDS = 5
TIME_REQUEST_INTERVAL_MS = SYNC_SECONDS * 500  # 2500 ms between time requests
SYNC_LOSS_MS = SYNC_SECONDS * 2200  # 11000 ms without a time answer -> not configured

# Client TX ring (STM32Hardware): 128 chunks of 64 bytes; a frame that does not fit is dropped
TX_CHUNK_BYTES = 64
TX_CHUNKS = 128

# Server timing, in seconds
SERVER_ATTEMPT_INTERVAL_S = 1.0  # wait after a topic request
SERVER_TIMEOUT_INTERVAL_S = 5.0  # sync timeout once setup/time traffic flows
SERVER_REOPEN_INTERVAL_S = 2.0  # serial session re-opens (and re-requests topics) after loss
SERVICE_CALL_TIMEOUT_S = 10.0  # the fork's default wait for a service response

LOG_DROPPED_TOO_LARGE = "Message from device dropped: message larger than buffer."
