"""CANopen SDO client and server (A3): expedited and segmented transfers as state machines.

Rule: pure. Feed a frame, get the next frame to send or the result; the link owns timeouts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import can

from joints.codecs.canopen.abort import SdoAbortCode, abort_error
from joints.codecs.canopen.cob import SDO_RX_BASE, SDO_SEGMENT, SDO_TX_BASE, check_mux, check_node
from joints.codecs.canopen.messages import (
    SdoAbort,
    SdoDownloadInitiate,
    SdoDownloadInitiateResponse,
    SdoDownloadSegment,
    SdoDownloadSegmentResponse,
    SdoUploadInitiate,
    SdoUploadInitiateResponse,
    SdoUploadSegment,
    SdoUploadSegmentRequest,
    decode,
    encode,
)
from joints.errors import DeviceRejected, EncodeError, FrameError, JointsError, ProtocolError, UnexpectedReply

__all__ = ["SdoClient", "SdoDone", "SdoFailed", "SdoRead", "SdoSend", "SdoServer", "SdoStep", "SdoWrite"]

# --- SDO client and server ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoSend:
    """Send ``frame``, then feed the reply."""

    frame: can.Message


@dataclass(frozen=True, slots=True)
class SdoDone:
    """The transfer finished: ``data`` is the uploaded value (empty for a download)."""

    data: bytes = b""


@dataclass(frozen=True, slots=True)
class SdoFailed:
    """The transfer ended with ``error``: send ``frame`` (our abort) if set, then raise ``error``.

    ``error`` is :class:`~joints.errors.DeviceRejected` (code = abort code) when the node aborted,
    a :class:`~joints.errors.PeerProtocolError` when its reply broke the protocol.
    """

    error: ProtocolError
    frame: can.Message | None = None


SdoStep = SdoSend | SdoDone | SdoFailed

_IDLE, _DOWNLOAD, _DOWNLOAD_SEGMENTS, _UPLOAD, _UPLOAD_SEGMENTS = range(5)


class SdoClient:
    """Master side of one node's SDO channel (expedited and segmented transfers).

    ``upload``/``download`` return the first frame to send; :meth:`feed` takes each reply (frames
    on 0x580+node) and returns what to do next. One transfer at a time.
    """

    def __init__(self, node: int) -> None:
        check_node(node)
        self.node = node
        self.tx_cob_id = SDO_TX_BASE + node  #: where replies come from
        self._state = _IDLE
        self._index = 0
        self._subindex = 0
        self._toggle = False
        self._data = b""  #: download: what remains to send; upload: what came so far
        self._size: int | None = None
        self._last_sent = False

    @property
    def busy(self) -> bool:
        return self._state != _IDLE

    def _start(self, index: int, subindex: int) -> None:
        if self.busy:
            raise ProtocolError(f"node {self.node}: an SDO transfer on 0x{self._index:04X}:{self._subindex:02X} "
                                "is still running (one transfer at a time)")
        check_mux(index, subindex)
        self._index, self._subindex, self._toggle = index, subindex, False

    def upload(self, index: int, subindex: int) -> can.Message:
        """Start reading ``index:subindex``."""
        self._start(index, subindex)
        self._state, self._data, self._size = _UPLOAD, b"", None
        return encode(SdoUploadInitiate(self.node, index, subindex))

    def download(self, index: int, subindex: int, data: bytes, *, segmented: bool = False) -> can.Message:
        """Start writing ``data`` to ``index:subindex`` (expedited when it fits in 4 bytes)."""
        if not data:
            raise EncodeError("an SDO download needs at least one byte")
        self._start(index, subindex)
        self._state = _DOWNLOAD
        if len(data) <= 4 and not segmented:
            self._data = b""
            return encode(SdoDownloadInitiate(self.node, index, subindex, bytes(data), True, len(data)))
        self._data = bytes(data)
        return encode(SdoDownloadInitiate(self.node, index, subindex, b"", False, len(data)))

    def abort(self, code: int = SdoAbortCode.TIMEOUT) -> can.Message | None:
        """End the running transfer (e.g. on a timeout): the abort frame to send, or None if idle."""
        if not self.busy:
            return None
        self._state = _IDLE
        return encode(SdoAbort(self.node, self._index, self._subindex, code, True))

    def _fail(self, error: ProtocolError, code: int | None) -> SdoFailed:
        frame = None
        if code is not None:
            frame = encode(SdoAbort(self.node, self._index, self._subindex, code, True))
        self._state = _IDLE
        return SdoFailed(error, frame)

    def _protocol_error(self, text: str, code: int) -> SdoFailed:
        return self._fail(UnexpectedReply(f"node {self.node}: SDO 0x{self._index:04X}:{self._subindex:02X}: {text}"),
                          code)

    def feed(self, frame: can.Message) -> SdoStep:
        """The next step after reply ``frame``.

        A frame that is not on 0x580+node, or one that comes while no transfer runs, raises
        :class:`~joints.errors.UnexpectedReply` and changes nothing (the link routes by COB-ID).
        """
        if frame.arbitration_id != self.tx_cob_id or frame.is_remote_frame:
            raise UnexpectedReply(f"node {self.node}: frame 0x{frame.arbitration_id:X} is not an SDO reply "
                                  f"(expected 0x{self.tx_cob_id:X})")
        if not self.busy:
            raise UnexpectedReply(f"node {self.node}: SDO reply while no transfer runs")
        try:
            reply = decode(frame)
        except FrameError as exc:
            return self._fail(exc, SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if isinstance(reply, SdoAbort):
            self._state = _IDLE
            return SdoFailed(abort_error(self.node, reply.index, reply.subindex, reply.code))
        state = self._state
        if state == _DOWNLOAD:
            if not isinstance(reply, SdoDownloadInitiateResponse):
                return self._protocol_error(f"expected a download response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if (reply.index, reply.subindex) != (self._index, self._subindex):
                return self._protocol_error(f"download response for 0x{reply.index:04X}:{reply.subindex:02X}",
                                            SdoAbortCode.GENERAL_ERROR)
            if not self._data:
                self._state = _IDLE
                return SdoDone()
            self._state = _DOWNLOAD_SEGMENTS
            return SdoSend(self._next_segment())
        if state == _DOWNLOAD_SEGMENTS:
            if not isinstance(reply, SdoDownloadSegmentResponse):
                return self._protocol_error(f"expected a segment response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if reply.toggle != self._toggle:
                return self._protocol_error("segment response toggle bit not alternated",
                                            SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            self._toggle = not self._toggle
            if self._last_sent:
                self._state = _IDLE
                return SdoDone()
            return SdoSend(self._next_segment())
        if state == _UPLOAD:
            if not isinstance(reply, SdoUploadInitiateResponse):
                return self._protocol_error(f"expected an upload response, got {type(reply).__name__}",
                                            SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if (reply.index, reply.subindex) != (self._index, self._subindex):
                return self._protocol_error(f"upload response for 0x{reply.index:04X}:{reply.subindex:02X}",
                                            SdoAbortCode.GENERAL_ERROR)
            if reply.expedited:
                self._state = _IDLE
                return SdoDone(reply.data)
            self._state, self._size, self._data = _UPLOAD_SEGMENTS, reply.size, b""
            return SdoSend(encode(SdoUploadSegmentRequest(self.node, self._toggle)))
        # _UPLOAD_SEGMENTS
        if not isinstance(reply, SdoUploadSegment):
            return self._protocol_error(f"expected an upload segment, got {type(reply).__name__}",
                                        SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if reply.toggle != self._toggle:
            return self._protocol_error("upload segment toggle bit not alternated",
                                        SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
        self._data += reply.data
        if self._size is not None and len(self._data) > self._size:
            return self._protocol_error(f"{len(self._data)} bytes uploaded, {self._size} indicated",
                                        SdoAbortCode.LENGTH_TOO_HIGH)
        if not reply.last:
            self._toggle = not self._toggle
            return SdoSend(encode(SdoUploadSegmentRequest(self.node, self._toggle)))
        if self._size is not None and len(self._data) != self._size:
            return self._protocol_error(f"{len(self._data)} bytes uploaded, {self._size} indicated",
                                        SdoAbortCode.LENGTH_TOO_LOW)
        self._state = _IDLE
        return SdoDone(self._data)

    def _next_segment(self) -> can.Message:
        chunk, self._data = self._data[:SDO_SEGMENT], self._data[SDO_SEGMENT:]
        self._last_sent = not self._data
        return encode(SdoDownloadSegment(self.node, self._toggle, chunk, self._last_sent))


#: read(index, subindex) -> the object's bytes (little-endian); raise DeviceRejected(code=abort code) to refuse
SdoRead = Callable[[int, int], bytes]
#: write(index, subindex, data); raise DeviceRejected(code=abort code) to refuse
SdoWrite = Callable[[int, int, bytes], None]


class SdoServer:
    """Node side of the SDO channel: answers each request frame (0x600+node) from an object dictionary.

    ``read``/``write`` reach the dictionary; they refuse by raising
    :class:`~joints.errors.DeviceRejected` with the abort code as ``code`` (any other
    :class:`~joints.errors.JointsError` becomes abort 0x08000000). A segmented download is written
    once, whole, after its last segment. Gate by NMT state before feeding (not in STOPPED).
    """

    def __init__(self, node: int, read: SdoRead, write: SdoWrite) -> None:
        check_node(node)
        self.node = node
        self.rx_cob_id = SDO_RX_BASE + node  #: where requests come from
        self._read = read
        self._write = write
        self.reset()

    def reset(self) -> None:
        """Forget a transfer in progress (NMT reset, or the twin's own SDO timeout)."""
        self._state = _IDLE
        self._index = 0
        self._subindex = 0
        self._toggle = False
        self._data = b""
        self._size: int | None = None

    def _abort(self, code: int, index: int | None = None, subindex: int | None = None) -> can.Message:
        frame = encode(SdoAbort(self.node, self._index if index is None else index,
                                self._subindex if subindex is None else subindex, code, False))
        self.reset()
        return frame

    def feed(self, frame: can.Message) -> can.Message | None:
        """The reply to request ``frame`` (None when nothing is to be sent, e.g. after a client abort)."""
        if frame.arbitration_id != self.rx_cob_id or frame.is_remote_frame:
            return None
        try:
            request = decode(frame)
        except FrameError:
            return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
        if isinstance(request, SdoAbort):
            self.reset()
            return None
        if isinstance(request, SdoUploadInitiate):
            return self._upload(request.index, request.subindex)
        if isinstance(request, SdoDownloadInitiate):
            return self._download(request)
        if isinstance(request, SdoUploadSegmentRequest):
            if self._state != _UPLOAD_SEGMENTS:
                return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if request.toggle != self._toggle:
                return self._abort(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            chunk, self._data = self._data[:SDO_SEGMENT], self._data[SDO_SEGMENT:]
            last = not self._data
            reply = encode(SdoUploadSegment(self.node, self._toggle, chunk, last))
            self._toggle = not self._toggle
            if last:
                self.reset()
            return reply
        if isinstance(request, SdoDownloadSegment):
            if self._state != _DOWNLOAD_SEGMENTS:
                return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID)
            if request.toggle != self._toggle:
                return self._abort(SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            self._data += request.data
            if self._size is not None and len(self._data) > self._size:
                return self._abort(SdoAbortCode.LENGTH_TOO_HIGH)
            reply = encode(SdoDownloadSegmentResponse(self.node, self._toggle))
            self._toggle = not self._toggle
            if not request.last:
                return reply
            if self._size is not None and len(self._data) != self._size:
                return self._abort(SdoAbortCode.LENGTH_TOO_LOW)
            failed = self._call_write(self._index, self._subindex, self._data)
            if failed is not None:
                return failed
            self.reset()
            return reply
        # block transfer, unknown specifiers, or a server frame on our request COB-ID
        return self._abort(SdoAbortCode.COMMAND_SPECIFIER_INVALID, *_mux_of(frame))

    def _upload(self, index: int, subindex: int) -> can.Message:
        self.reset()
        try:
            data = bytes(self._read(index, subindex))
        except DeviceRejected as exc:
            return self._abort(exc.code, index, subindex)
        except JointsError:
            return self._abort(SdoAbortCode.GENERAL_ERROR, index, subindex)
        if 1 <= len(data) <= 4:
            return encode(SdoUploadInitiateResponse(self.node, index, subindex, data, True, len(data)))
        self._state, self._index, self._subindex, self._data = _UPLOAD_SEGMENTS, index, subindex, data
        return encode(SdoUploadInitiateResponse(self.node, index, subindex, b"", False, len(data)))

    def _download(self, request: SdoDownloadInitiate) -> can.Message:
        self.reset()
        index, subindex = request.index, request.subindex
        if request.expedited:
            failed = self._call_write(index, subindex, request.data)
            return failed if failed is not None else encode(SdoDownloadInitiateResponse(self.node, index, subindex))
        self._state, self._index, self._subindex, self._size = _DOWNLOAD_SEGMENTS, index, subindex, request.size
        return encode(SdoDownloadInitiateResponse(self.node, index, subindex))

    def _call_write(self, index: int, subindex: int, data: bytes) -> can.Message | None:
        try:
            self._write(index, subindex, data)
        except DeviceRejected as exc:
            return self._abort(exc.code, index, subindex)
        except JointsError:
            return self._abort(SdoAbortCode.GENERAL_ERROR, index, subindex)
        return None


def _mux_of(frame: can.Message) -> tuple[int, int]:
    data = bytes(frame.data).ljust(4, b"\x00")
    return data[1] | data[2] << 8, data[3]
