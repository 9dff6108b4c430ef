from .diagnose import (
    diagnose as diagnose,
    write_diagnosis_report as write_diagnosis_report,
)
