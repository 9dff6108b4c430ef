from .control import (
    CONTROLS as CONTROLS,
    ControlDetection as ControlDetection,
    control_name as control_name,
    detect_control as detect_control,
    resolve_control as resolve_control,
)
from .csv import (
    read_canonical as read_canonical,
    read_csv as read_csv,
    write_csv as write_csv,
)
from .json_file import parse_json as parse_json, read_json as read_json
from .options import METADATA_KEYS as METADATA_KEYS, ReadOptions as ReadOptions
from .preamble import MetadataConflictWarning as MetadataConflictWarning
from .protocol_file import ProtocolFile as ProtocolFile, read_protocol as read_protocol
from .raw import read_test as read_test
from .slack import (
    SlackReport as SlackReport,
    SlackStretch as SlackStretch,
    force_noise as force_noise,
)
from .testdata import (
    TestData as TestData,
    mask_slack as mask_slack,
    pushing_samples as pushing_samples,
)
