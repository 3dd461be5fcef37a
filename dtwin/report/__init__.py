"""What the commands report, without the command line: the analyses behind `dtwin freqs`, `modes`,
`stiffness`, `spectrum`, `simulate` and `record info` (`analyses`), the paper's Section 6 drive
comparison (`drive_comparison`) and its figures (`drive_comparison_figures`), and the HTML
report of an output folder (`html_report`). Above the model, simulation, spec, signal and
identification."""
