"""File readers and writers (KF-GINS text formats: :mod:`insnav.io.kfgins`)."""
