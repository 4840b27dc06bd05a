"""Fault injection: the cases ``uav-el fault-table`` replays through the command line (bad inputs, hostile
applicants, forged runs), each with the behaviour it must show. It sits above everything it exercises."""
