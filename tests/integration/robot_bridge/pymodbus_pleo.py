#!/usr/bin/python3
"""A minimal Pleo controller on pymodbus (an independent Modbus implementation).

It follows the register map in docs/robot_bridge_registers.md just enough to
interoperate with robot_bridge: a write that changes CMD_SEQUENCE (holding 2)
is applied at once (no animation delay) and acknowledged in APPLIED_SEQUENCE
(input 2). Usage: pymodbus_pleo.py PORT_FILE   (listens on 127.0.0.1, port 0)
"""
import asyncio
import os
import sys

from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                ModbusSlaveContext)
from pymodbus.server.async_io import ModbusTcpServer


class PleoContext(ModbusSlaveContext):
    def setValues(self, fc_as_hex, address, values):
        super().setValues(fc_as_hex, address, values)
        if self.decode(fc_as_hex) != "h":
            return
        if address <= 2 < address + len(values):
            hr = self.store["h"].getValues(0, 3)
            ir = self.store["i"]
            if hr[2] != 0 and hr[2] != ir.getValues(2, 1)[0]:
                # shown emotion, shown intensity, applied sequence, state following
                ir.setValues(0, [hr[0], hr[1], hr[2], 0])
                ir.setValues(9, [hr[0]])


async def main(port_file):
    ir = [0, 500, 0, 0, 1000, 0, 0x0100, 0, 0, 0, 0x504C]
    slave = PleoContext(
        di=ModbusSequentialDataBlock(0, [0] * 8),
        co=ModbusSequentialDataBlock(0, [0] * 1),
        hr=ModbusSequentialDataBlock(0, [0, 500, 0, 0, 2000]),
        ir=ModbusSequentialDataBlock(0, ir),
        zero_mode=True,
    )
    context = ModbusServerContext(slaves={1: slave}, single=False)
    server = ModbusTcpServer(context, address=("127.0.0.1", 0), allow_reuse_address=True)
    task = asyncio.create_task(server.serve_forever())
    await server.serving
    port = server.server.sockets[0].getsockname()[1]
    tmp = port_file + ".tmp"
    with open(tmp, "w") as f:
        f.write(f"{port}\n")
    os.rename(tmp, port_file)
    print(f"pymodbus_pleo: listening tcp 127.0.0.1:{port}", flush=True)
    await task


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: pymodbus_pleo.py PORT_FILE")
    asyncio.run(main(sys.argv[1]))
