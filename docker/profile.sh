# /etc/profile.d/snakekit.sh: the kit's commands (snakekit, nbgrader, jupyter) in every shell.
# A login shell (JupyterLab's terminals run `sh -l` or `bash -l`) reads /etc/profile, which sets
# PATH afresh and would drop the venv the image's environment put first; this puts it back.
case ":$PATH:" in
  *:/opt/venv/bin:*) ;;
  *) PATH=/opt/venv/bin:$PATH ;;
esac
export PATH
