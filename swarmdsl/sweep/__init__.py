"""Many runs of one program: parameter grids x replicate seeds, on processes or Dask."""
