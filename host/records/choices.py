"""Choices a file records and the command line offers, kept where importing them costs
nothing (no numpy): a command's parser lists them for --help, the file formats check them.
"""

__all__ = ["COSTS", "RECORD_FIELDS", "RESPONSES"]

#: What a fit minimised (host/estimate/fit.py; MODELS.json's ``cost``): CIFER's J, or the
#: weighted relative complex error alone.
COSTS = ("j", "relative")
#: HQ_SYSID_SAMPLE's fields a record read as one (``identify --from-record``) may take as its
#: input or output.
RECORD_FIELDS = ("axis_cmd", "rate_sp", "rate", "angle_sp", "angle")
#: What a rate or angle sweep measures (``sweep --response``, ``identify --response``):
#: ``loop``, its setpoint to its response (the angle or rate setpoint to the angle or rate);
#: ``plant``, the mixer's input to the rate (what a mixer sweep measures), estimated against
#: the excitation that enters at the setpoint, so that the controller's reaction to a
#: disturbance is no part of it.
RESPONSES = ("loop", "plant")
