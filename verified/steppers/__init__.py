"""One verified step for one set kind: the stepper protocol, the QR-Lohner step, the
second-order mean-value step, the Taylor-model composition step, and the table of set kinds.
"""
