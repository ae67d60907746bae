"""What cwrend writes: atomic files, Arrow/Parquet tables and Rerun recordings."""
