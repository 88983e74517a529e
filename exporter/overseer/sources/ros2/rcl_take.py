"""Raw messages with their publisher's GID, taken from an rclpy subscription through rcl itself.

rclpy hands a subscription's callback the message and, at most, its timestamps and sequence numbers; the
publisher's GID, which tells which node published it (`/diagnostics` is shared by every node of every
robot on a domain), stays in rcl's `rmw_message_info_t`. So the source's subscriptions are left out of any
executor: rcl wakes the source when messages arrive (`wake_on_new_message`), and `take` reads them,
serialized, with their message info, through `rcl_take_serialized_message`.

The wake-up runs no Python. rcl calls it from the middleware's receive thread, which holds its receive
lock meanwhile, and rclpy holds the GIL in calls that wait for that lock (`create_subscription`): a
Python callback there waited for the GIL while the node's thread waited for the lock, and the exporter
froze (seen under load in CI). The callback is libc's `eventfd_write(fd, count)` itself, the eventfd's
number passed as rcl's `user_data`: rcl calls `callback(user_data, count)`, and both arguments go in the
registers `eventfd_write(int fd, eventfd_t value)` reads them from (x86-64 and AArch64 calling conventions).

The structures below are rcl's and rmw's (Jazzy: `RMW_GID_STORAGE_SIZE` 16); rclpy has loaded the
libraries before this module is imported.
"""

from __future__ import annotations

import ctypes
from typing import NamedTuple

RMW_GID_STORAGE_SIZE = 16
RCL_RET_OK = 0
RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401


class _Allocator(ctypes.Structure):
    _fields_ = [
        ("allocate", ctypes.c_void_p),
        ("deallocate", ctypes.c_void_p),
        ("reallocate", ctypes.c_void_p),
        ("zero_allocate", ctypes.c_void_p),
        ("state", ctypes.c_void_p),
    ]


class _SerializedMessage(ctypes.Structure):  # rcutils_uint8_array_t
    _fields_ = [
        ("buffer", ctypes.POINTER(ctypes.c_uint8)),
        ("buffer_length", ctypes.c_size_t),
        ("buffer_capacity", ctypes.c_size_t),
        ("allocator", _Allocator),
    ]


class _Gid(ctypes.Structure):  # rmw_gid_t
    _fields_ = [
        ("implementation_identifier", ctypes.c_char_p),
        ("data", ctypes.c_uint8 * RMW_GID_STORAGE_SIZE),
    ]


class _MessageInfo(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [
        ("source_timestamp", ctypes.c_int64),
        ("received_timestamp", ctypes.c_int64),
        ("publication_sequence_number", ctypes.c_uint64),
        ("reception_sequence_number", ctypes.c_uint64),
        ("publisher_gid", _Gid),
        ("from_intra_process", ctypes.c_bool),
    ]


_rcl = ctypes.CDLL("librcl.so")
_rcutils = ctypes.CDLL("librcutils.so")
_rcutils.rcutils_get_default_allocator.restype = _Allocator
_rcutils.rcutils_uint8_array_init.argtypes = [
    ctypes.POINTER(_SerializedMessage),
    ctypes.c_size_t,
    ctypes.POINTER(_Allocator),
]
_rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_SerializedMessage)]
_rcl.rcl_take_serialized_message.argtypes = [
    ctypes.c_void_p,
    ctypes.POINTER(_SerializedMessage),
    ctypes.POINTER(_MessageInfo),
    ctypes.c_void_p,
]
# rcl_event_callback_t, void (*)(const void * user_data, size_t number_of_events): eventfd_write's address
_rcl.rcl_subscription_set_on_new_message_callback.argtypes = [
    ctypes.c_void_p,
    ctypes.c_void_p,
    ctypes.c_void_p,
]
_EVENTFD_WRITE = ctypes.cast(ctypes.CDLL(None).eventfd_write, ctypes.c_void_p).value


class TakenMessage(NamedTuple):
    """One serialized message (CDR with its encapsulation header) and its publisher's GID."""

    payload: bytes
    publisher_gid: bytes


class RawTaker:
    """Takes serialized messages with their message info; one per thread that takes."""

    def __init__(self, initial_capacity: int = 4096) -> None:
        """A reusable buffer of `initial_capacity` bytes, grown by rmw as messages need."""
        self._allocator = _rcutils.rcutils_get_default_allocator()
        self._message = _SerializedMessage()
        self._info = _MessageInfo()
        message, allocator = ctypes.byref(self._message), ctypes.byref(self._allocator)
        if _rcutils.rcutils_uint8_array_init(message, initial_capacity, allocator):
            raise MemoryError("rcutils_uint8_array_init failed")

    def take(self, subscription: int) -> TakenMessage | None:
        """The next message of the rcl subscription at address `subscription`, or None when there is none."""
        result = _rcl.rcl_take_serialized_message(
            subscription, ctypes.byref(self._message), ctypes.byref(self._info), None
        )
        if result == RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            return None
        if result != RCL_RET_OK:
            raise OSError(f"rcl_take_serialized_message failed with {result}")
        message = self._message
        return TakenMessage(
            ctypes.string_at(message.buffer, message.buffer_length), bytes(self._info.publisher_gid.data)
        )

    def close(self) -> None:
        """Free the buffer."""
        _rcutils.rcutils_uint8_array_fini(ctypes.byref(self._message))


def wake_on_new_message(subscription: int, eventfd: int | None) -> None:
    """Have rcl add the number of each batch of new messages to `eventfd` as they arrive (None: stop).

    Setting it when messages are waiting already adds their number at once. Clearing it waits for a
    wake-up under way to end, so the eventfd may be closed afterwards.
    """
    if eventfd is None:
        _rcl.rcl_subscription_set_on_new_message_callback(subscription, None, None)
        return
    result = _rcl.rcl_subscription_set_on_new_message_callback(subscription, _EVENTFD_WRITE, eventfd)
    if result != RCL_RET_OK:
        raise OSError(f"rcl_subscription_set_on_new_message_callback failed with {result}")
