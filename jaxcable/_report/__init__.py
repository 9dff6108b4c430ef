from .fit_report import (
    Progress as Progress,
    _grid as _grid,
    _time_axis as _time_axis,
    model_elongations as model_elongations,
    write_report as write_report,
)
