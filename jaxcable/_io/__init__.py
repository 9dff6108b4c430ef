from .json_file import parse_json as parse_json, read_json as read_json
from .protocol_file import (
    read_protocol as read_protocol,
)
from .readers import (
    TestData as TestData,
    read_csv as read_csv,
    read_test as read_test,
    write_csv as write_csv,
)
