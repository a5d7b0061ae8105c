"""The data: chunk codecs, HDF5 shards, the dataset folder and its reader, the rollout that writes
them, and the audit (``info``/``verify``) that reads them back."""
