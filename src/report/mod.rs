//! Reports: HTML (minijinja + plotters SVG) and diff across results.
