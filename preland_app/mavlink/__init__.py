"""preland's own MAVLink dialect and its transport: the thesis' fault-injection command."""
