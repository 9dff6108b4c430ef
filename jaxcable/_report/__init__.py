from .._diagnose import model_elongations as model_elongations
from .diagnosis_report import (
    DIAGNOSIS_REPORT_FILES as DIAGNOSIS_REPORT_FILES,
    write_diagnosis_report as write_diagnosis_report,
)
from .fit_report import (
    FIT_REPORT_FILES as FIT_REPORT_FILES,
    summary_markdown as summary_markdown,
    write_report as write_report,
)
from .plots import (
    plot_loops as plot_loops,
    plot_residuals as plot_residuals,
    save_png as save_png,
)
