"""Files in and out: images, atomic writes, checked paths and result sets."""
