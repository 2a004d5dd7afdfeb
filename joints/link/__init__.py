"""Link: the one place for waiting - request/reply by protocol rule, send-only frames, subscriptions
for unsolicited frames, timeouts, retries, echo skipping, tracing; one lock per bus."""

from joints.link.base import Framing, Link, RetryPolicy, Rule, Subscription
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace, TraceRecord

__all__ = ["Framing", "Link", "ModbusLink", "RetryPolicy", "Rule", "Subscription", "Trace", "TraceRecord"]
