from .._diagnose import model_elongations as model_elongations
from .._progress import Progress as Progress
from .diagnosis_report import write_diagnosis_report as write_diagnosis_report
from .fit_report import (
    summary_markdown as summary_markdown,
    write_report as write_report,
)
from .plots import plot_loops as plot_loops, plot_residuals as plot_residuals
