"""The model: the mutual-embedding model (MEM), word vectors, the trainer, evaluation and t-SNE,
and the MEM as a reward signal."""
