//! Charts of the analysis (being written)
