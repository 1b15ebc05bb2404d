"""File formats drem reads and writes: model archives and their metadata, event exports, CSV and PDF output.

Pure: bytes and folders in, typed values out (or the other way); no boto3, no HTTP."""
