"""Map quality predicted from a floorplan: dataset, models, model file, cross-validation."""
