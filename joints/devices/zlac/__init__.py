"""ZLAC8015D dual-channel hub servo driver (Zhongling): Modbus RTU register table."""
