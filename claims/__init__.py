"""The claims registry (issue 24): every number of the docs' verdict and results tables, the code
that regenerates it, its recorded value and tolerance, and the doc table it fills. `swarmhil
claims` reruns them; docs/claims.md says how."""
