"""The classical baselines of the paper's Table 3: bag of visual words, and VGG16 features with a
linear SVM."""
