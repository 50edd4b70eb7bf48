"""The MPU6050 as the simulator presents it: its noise, bias and DMP latency, and the FIFO
packets the firmware's driver reads.
"""
