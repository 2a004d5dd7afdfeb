"""Link: the one place for waiting - request/reply matching, timeouts, retries, echo skipping, tracing."""

from joints.link.modbus import ModbusLink, RetryPolicy
from joints.link.trace import Trace, TraceRecord

__all__ = ["ModbusLink", "RetryPolicy", "Trace", "TraceRecord"]
