"""CANopen (CiA 301) codec over python-can frames, sans-I/O, for both sides (master and node).

Rule: pure. Frames are :class:`can.Message` (python-can's frame class; this module is imported only
when a CAN bus is used). ``decode(frame)`` returns a frozen message, ``encode(message)`` a frame;
:func:`classify` says which service a frame belongs to and which node, so a link can route frames
nobody asked for (heartbeats, EMCY, TPDOs) without decoding them. The SDO client and server are
state machines: feed a frame, get the next frame to send or the result. Nothing here reads a clock:
heartbeat and guarding periods, SDO timeouts, event timers and SYNC periods belong to the link or
the twin, which call :meth:`SdoClient.abort` on a timeout.

Source: the eRunner manual v1.7 chapter 5 (NMT stop/reset communication, boot-up on 0x700+node,
expedited SDO on 0x600/0x580+node, COB-ID SYNC 0x1005 = 0x80, communication cycle 0x1006, RPDO1
on 0x200+node, node guarding by remote frames: chapter 6 item 3 "eRunner涉及报文除心跳检测均为数据帧").
Chapter 5 shows only those services; everything else follows CiA 301 v4.2 and is listed here as an
assumption to confirm on a real eRob:

* A1 COB-IDs follow the CiA 301 pre-defined connection set (:func:`classify`); a PDO moved to
  another COB-ID must be routed by the link's own table.
* A2 Node guarding: master sends a remote frame on 0x700+node (DLC 1); the node answers one byte,
  bit 7 a toggle that starts at 0 after NMT reset communication and alternates, bits 6..0 the NMT
  state. A guarding reply has the heartbeat's COB-ID and layout, so :func:`decode` returns
  :class:`Heartbeat` for both (``toggle`` set from bit 7); :class:`GuardingMaster` checks the toggle.
  COB-IDs 0x7E4/0x7E5 (LSS) are classified as the heartbeats of nodes 100/101 (LSS is not used).
* A3 SDO: expedited and segmented transfers only. Block transfer (client command specifiers 5 and
  6) is not implemented: :class:`SdoServer` answers it with abort 0x05040001, :class:`SdoClient`
  never starts one. An expedited transfer without size indication carries 4 data bytes.
  Reserved bytes are ignored on decode and sent as 0; SDO frames must carry 8 data bytes.
* A4 EMCY: 8 bytes (error code LE16, error register 0x1001, 5 manufacturer bytes); shorter frames
  of at least 3 bytes are accepted (missing manufacturer bytes read as 0) because drives differ. Error
  code 0x0000 is "error reset / no error". The eRob's own code meanings belong to
  :mod:`joints.devices.erob.faults`; :func:`emcy_class_text` gives the CiA 301 class only.
* A5 SYNC: DLC 0, or DLC 1 with a counter 1..240 (CiA 301 7.2.5). TIME is classified, not decoded.
* A6 PDO: at most 64 mapped bits, little-endian bit packing in mapping order. A received PDO
  longer than its mapping is accepted (extra bytes ignored); a shorter one is a
  :class:`~joints.errors.FrameError` (CiA 301: "not processed", EMCY 0x8210).
* A7 NMT: the node state machine of CiA 301 7.3.2.2 (:func:`nmt_transition`); after a reset the
  node sends its boot-up (state 0) and is then PRE-OPERATIONAL. Services per state:
  :data:`SERVICES_BY_STATE`.
"""

from __future__ import annotations

from joints.codecs.canopen.abort import (
    ABORT_TEXT,
    SdoAbortCode,
    abort_error,
    abort_text,
)
from joints.codecs.canopen.cob import (
    EMCY_BASE,
    ERROR_CONTROL_BASE,
    MAX_NODE,
    NMT_ID,
    RPDO_BASE,
    SDO_RX_BASE,
    SDO_SEGMENT,
    SDO_TX_BASE,
    SYNC_ID,
    TIME_ID,
    TPDO_BASE,
    Kind,
    Route,
    classify,
    pdo_cob_id,
)
from joints.codecs.canopen.emcy import (
    ERROR_REGISTER_BITS,
    emcy_class_text,
)
from joints.codecs.canopen.guarding import (
    GuardingMaster,
    GuardingSlave,
)
from joints.codecs.canopen.messages import (
    BootUp,
    Emcy,
    GuardRequest,
    Heartbeat,
    Message,
    Nmt,
    Other,
    Pdo,
    SdoAbort,
    SdoDownloadInitiate,
    SdoDownloadInitiateResponse,
    SdoDownloadSegment,
    SdoDownloadSegmentResponse,
    SdoRequest,
    SdoResponse,
    SdoUnsupported,
    SdoUploadInitiate,
    SdoUploadInitiateResponse,
    SdoUploadSegment,
    SdoUploadSegmentRequest,
    Sync,
    decode,
    encode,
)
from joints.codecs.canopen.nmt import (
    AFTER_BOOT_UP,
    SERVICES_BY_STATE,
    NmtCommand,
    NmtState,
    nmt_transition,
)
from joints.codecs.canopen.pdo import (
    DUMMY_BITS,
    MAX_PDO_BITS,
    PDO_INVALID,
    PDO_NO_RTR,
    SYNC_PRODUCER,
    PdoComm,
    PdoMapEntry,
    SdoWriteSpec,
    pack_pdo,
    pdo_configuration_writes,
    pdo_disable_writes,
    pdo_indices,
    pdo_length,
    pdo_packer,
    pdo_unpacker,
    unpack_pdo,
)
from joints.codecs.canopen.sdo import (
    SdoClient,
    SdoDone,
    SdoFailed,
    SdoRead,
    SdoSend,
    SdoServer,
    SdoStep,
    SdoWrite,
)

__all__ = [
    "ABORT_TEXT",
    "AFTER_BOOT_UP",
    "DUMMY_BITS",
    "EMCY_BASE",
    "ERROR_CONTROL_BASE",
    "ERROR_REGISTER_BITS",
    "MAX_NODE",
    "MAX_PDO_BITS",
    "NMT_ID",
    "PDO_INVALID",
    "PDO_NO_RTR",
    "RPDO_BASE",
    "SDO_RX_BASE",
    "SDO_SEGMENT",
    "SDO_TX_BASE",
    "SERVICES_BY_STATE",
    "SYNC_ID",
    "SYNC_PRODUCER",
    "TIME_ID",
    "TPDO_BASE",
    "BootUp",
    "Emcy",
    "GuardRequest",
    "GuardingMaster",
    "GuardingSlave",
    "Heartbeat",
    "Kind",
    "Message",
    "Nmt",
    "NmtCommand",
    "NmtState",
    "Other",
    "Pdo",
    "PdoComm",
    "PdoMapEntry",
    "Route",
    "SdoAbort",
    "SdoAbortCode",
    "SdoClient",
    "SdoDone",
    "SdoDownloadInitiate",
    "SdoDownloadInitiateResponse",
    "SdoDownloadSegment",
    "SdoDownloadSegmentResponse",
    "SdoFailed",
    "SdoRead",
    "SdoRequest",
    "SdoResponse",
    "SdoSend",
    "SdoServer",
    "SdoStep",
    "SdoUnsupported",
    "SdoUploadInitiate",
    "SdoUploadInitiateResponse",
    "SdoUploadSegment",
    "SdoUploadSegmentRequest",
    "SdoWrite",
    "SdoWriteSpec",
    "Sync",
    "abort_error",
    "abort_text",
    "classify",
    "decode",
    "emcy_class_text",
    "encode",
    "nmt_transition",
    "pack_pdo",
    "pdo_cob_id",
    "pdo_configuration_writes",
    "pdo_disable_writes",
    "pdo_indices",
    "pdo_length",
    "pdo_packer",
    "pdo_unpacker",
    "unpack_pdo",
]
