"""Temporary: the names `jaxcable/__init__.py` imports from this module, kept until it
imports them from `jaxcable._io`; then this module goes."""

from .csv import read_csv as read_csv, write_csv as write_csv
from .raw import read_test as read_test
from .slack import SlackReport as SlackReport, SlackStretch as SlackStretch
from .testdata import TestData as TestData, mask_slack as mask_slack


# `jaxcable.Test`, removed with this module.
Test = TestData
